"""The engine's parts, made and wired together (their roles: `core`'s module docstring)."""

from __future__ import annotations

import threading
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from servant_core.engine.arm import ArmControl
from servant_core.engine.bus import EventBus
from servant_core.engine.judging import Judge
from servant_core.engine.models import Models
from servant_core.engine.sense_devices import SenseDevices
from servant_core.engine.unknown_places import UnknownPlaces
from servant_core.fusion import FusionPolicy, SequentialFusion
from servant_core.fusion.pipeline import DecisionPipeline
from servant_core.fusion.smoothing import SceneSmoother
from servant_core.recognisers import FRESH_METHODS, Recogniser
from servant_core.senses import SENSES

if TYPE_CHECKING:
    from servant_core.engine.core import Engine


@dataclass(frozen=True)
class EngineParts:
    """What an `Engine` coordinates: the events' `bus`, the `arm`, the `decisions` every opinion
    goes to, the unknown `places`, the `models`, the `judge` and the sense `devices`, with the
    `lock` that guards the models, the fusion and the scores together."""

    lock: threading.RLock
    bus: EventBus
    arm: ArmControl
    decisions: DecisionPipeline
    places: UnknownPlaces
    models: Models
    judge: Judge
    devices: SenseDevices

    @classmethod
    def build(
        cls,
        engine: Engine,
        *,
        acoustic: Recogniser | None,
        visual: Recogniser | None,
        sample_recognisers: Mapping[str, Recogniser],
        fusion: FusionPolicy | None,
        smoother: SceneSmoother | None,
        fresh_methods: Mapping[str, str],
        model_path: str | Path | None,
        confidence_threshold: float | None,
        spectrum_fps: float,
        spectrum_size: int,
    ) -> EngineParts:
        """The parts over what `engine` holds already: its clock, senses and windows' length,
        its `ask_after_s` and `reopen_seconds` (the constructor's arguments: `Engine`)."""
        lock = threading.RLock()
        bus = EventBus(engine.clock)
        arm = ArmControl(bus, engine.reopen_seconds)
        roles = ["acoustic", "visual", *(SENSES[sense].role for sense in engine.samples)]
        policy = fusion if fusion is not None else SequentialFusion()
        decisions = DecisionPipeline(policy, smoother, roles)
        places = UnknownPlaces(
            bus, ask_after_s=engine.ask_after_s, window_seconds=engine.window_seconds
        )
        models = Models(
            acoustic=acoustic,
            visual=visual,
            samples=sample_recognisers,
            decisions=decisions,
            bus=bus,
            lock=lock,
            fresh_methods={**FRESH_METHODS, **fresh_methods},
            path=Path(model_path) if model_path else None,
            window_seconds=engine.window_seconds,
            on_new_sound=lambda: judge.forget(),
        )
        judge = Judge(
            models=models,
            decisions=decisions,
            places=places,
            bus=bus,
            arm=arm,
            lock=lock,
            confidence_threshold=confidence_threshold,
        )
        devices = judged_devices(engine, judge, bus, spectrum_fps, spectrum_size)
        return cls(lock, bus, arm, decisions, places, models, judge, devices)


def judged_devices(
    engine: Engine, judge: Judge, bus: EventBus, spectrum_fps: float, spectrum_size: int
) -> SenseDevices:
    """The engine's sense devices, each window and sample sense's window judged by `judge` (a
    failing prediction reported, not raised)."""
    return SenseDevices(
        engine.audio,
        engine.camera,
        engine.samples,
        bus,
        on_window=lambda window, rate: judge.guarded(
            "acoustic prediction", judge.on_window, window, rate
        ),
        on_samples=lambda name, window, rate: judge.guarded(
            f"{name} prediction", judge.on_samples, name, window, rate
        ),
        window_seconds=engine.window_seconds,
        reopen_seconds=engine.reopen_seconds,
        spectrum_fps=spectrum_fps,
        spectrum_size=spectrum_size,
    )
