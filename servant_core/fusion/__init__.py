"""Fusion policies: when do a sound and a picture make a scene decision.

A policy is fed predictions with their times and returns the events it produces (`Decision`,
`FusionState`); time is always passed in. The learned policy also takes any sense's opinion with
its scores (`LearnedFusion.on_sense`), and `scores=` on `on_acoustic`/`on_visual`; built from the
registry with a config alone it has no net and decides as the parallel policy. Who feeds a policy
is `fusion.pipeline.DecisionPipeline`, for the live engine and the command line alike.
"""

from __future__ import annotations

from typing import ClassVar, Protocol

from servant_core.choices import DEFAULT_POLICY
from servant_core.events import Decision, FusionState
from servant_core.fusion.learned import LearnedFusion
from servant_core.fusion.net import FusionNet
from servant_core.fusion.parallel import ParallelFusion
from servant_core.fusion.sequential import FusionConfig, SequentialFusion, scene_line


class FusionPolicy(Protocol):
    hears_every_sense: ClassVar[bool]  # takes `on_sense(sense, scene, confidence, t, scores)`
    weighs_scores: ClassVar[bool]  # takes `scores=` on `on_acoustic` and `on_visual`
    config: FusionConfig  # its windows

    def on_acoustic(
        self, scene: str | None, confidence: float, t: float
    ) -> list[Decision | FusionState]: ...
    def on_visual(
        self, scene: str | None, confidence: float, t: float
    ) -> list[Decision | FusionState]: ...
    def tick(self, t: float) -> list[Decision | FusionState]: ...
    def wants_picture(self, t: float) -> bool: ...
    def state(self, t: float) -> FusionState: ...


POLICIES: dict[str, type] = {
    "sequential": SequentialFusion,
    "parallel": ParallelFusion,
    "learned": LearnedFusion,
}


__all__ = [
    "DEFAULT_POLICY",
    "POLICIES",
    "FusionConfig",
    "FusionNet",
    "FusionPolicy",
    "LearnedFusion",
    "ParallelFusion",
    "SequentialFusion",
    "scene_line",
]
