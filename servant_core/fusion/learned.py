"""The learned fusion policy: `LearnedFusion` pools each sense's recent opinions and decides as
soon as its `FusionNet` (`fusion.net`) is sure enough; without a usable net it is the parallel
policy."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from servant_core.events import Decision, FusionState
from servant_core.fusion.net import FusionNet, Pooled, leaned_on
from servant_core.fusion.parallel import ParallelFusion
from servant_core.fusion.sequential import AcousticWindow, FusionConfig, scene_line
from servant_core.recognisers.base import UNKNOWN


@dataclass(frozen=True)
class Opinion:
    t: float
    scores: dict[str, float]
    unknown: bool
    confidence: float


class LearnedFusion(AcousticWindow):
    """The policy around a `FusionNet`: `on_sense` for any sense, `on_acoustic`/`on_visual` for
    the two the rule policies know. A sense's opinions count while younger than its staleness
    limit (`staleness[sense]`; by default the acoustic window for sound, the confirm window for
    the others) and the last `net.pool` of them are averaged. Like the parallel policy it looks
    all the time, and says `No scene detected` when `acoustic_window_s` passes undecided.
    Without a net, or with one whose `threshold_` is 1 (it never reached the target precision),
    every call goes to a `ParallelFusion`: the rule policy is the fallback.
    """

    hears_every_sense = True

    def __init__(
        self,
        config: FusionConfig | None = None,
        net: FusionNet | None = None,
        *,
        staleness: Mapping[str, float] | None = None,
    ) -> None:
        self.config = config or FusionConfig()
        usable = net is not None and hasattr(net, "coefs_") and net.threshold_ < 1.0
        self.net = net if usable else None
        self.fallback = ParallelFusion(self.config) if self.net is None else None
        self.staleness = dict(staleness or {})
        self.last_picture_at: float | None = None
        self._restart()

    def _restart(self) -> None:
        self.opinions: dict[str, list[Opinion]] = {}
        self.opened_at: float | None = None
        self.acoustic_confidence = 0.0

    def stale_after(self, sense: str) -> float:
        default = (
            self.config.acoustic_window_s if sense == "audio" else self.config.confirm_window_s
        )
        return self.staleness.get(sense, default)

    def _fresh(self, t: float) -> dict[str, Pooled]:
        """Each sense's pooled opinion: mean scores, unknown share and number of its recent
        ones."""
        assert self.net is not None
        pooled: dict[str, Pooled] = {}
        for sense, said in self.opinions.items():
            recent = [o for o in said if t - o.t <= self.stale_after(sense)][-self.net.pool :]
            if recent:
                scenes = {s for o in recent for s in o.scores}
                scores = {
                    s: sum(o.scores.get(s, 0.0) for o in recent) / len(recent) for s in scenes
                }
                unknown = sum(o.unknown for o in recent) / len(recent)
                pooled[sense] = (scores, unknown, len(recent))
        return pooled

    def _leading(self, t: float) -> tuple[str | None, float, dict[str, Any]]:
        pooled = self._fresh(t)
        if not pooled:
            return None, 0.0, pooled
        assert self.net is not None
        proba = self.net.predict_proba(self.net.features(pooled))[0]
        j = int(np.argmax(proba))
        return self.net.scenes_[j], float(proba[j]), pooled

    def state(self, t: float) -> FusionState:
        if self.fallback is not None:
            return self.fallback.state(t)
        scene, top, pooled = self._leading(t)
        scene = scene if top >= 0.5 else None  # a weak lead is no scene being confirmed
        pictures = sum(
            1 for o in self.opinions.get("image", []) if t - o.t <= self.stale_after("image")
        )
        phase = "confirming" if pooled else "listening"
        return FusionState(t, phase, scene, self.seconds_left(t), pictures)

    def tick(self, t: float) -> list[Decision | FusionState]:
        if self.fallback is not None:
            return self.fallback.tick(t)
        for sense in list(self.opinions):
            limit = self.stale_after(sense)
            self.opinions[sense] = [o for o in self.opinions[sense] if t - o.t <= limit]
        return super().tick(t)

    def on_sense(
        self,
        sense: str,
        scene: str | None,
        confidence: float,
        t: float,
        scores: Mapping[str, float] | None = None,
    ) -> list[Decision | FusionState]:
        """One sense's opinion at time `t`: its scene (None or `<unknown>`: it named none), its
        confidence, and its probability per scene (without them, the scene counts as certain)."""
        if self.fallback is not None:
            if sense == "audio":
                return self.fallback.on_acoustic(scene, confidence, t)
            if sense == "image":
                return self.fallback.on_visual(scene, confidence, t)
            return [*self.fallback.tick(t), self.fallback.state(t)]  # the rules know two senses
        events = self.tick(t)
        unknown = scene is None or scene == UNKNOWN
        if scores is not None:
            said = {str(s): float(p) for s, p in scores.items() if math.isfinite(float(p))}
        else:
            said = {} if unknown else {str(scene): 1.0}
        self.opinions.setdefault(sense, []).append(Opinion(t, said, unknown, float(confidence)))
        if sense == "audio":
            self.acoustic_confidence = float(confidence)
        if sense == "image":
            self.last_picture_at = t
        if self.opened_at is None:
            self.opened_at = t
        return [*events, *self._decide(t)]

    def _latest_confidence(self, sense: str) -> float:
        said = self.opinions.get(sense)
        return said[-1].confidence if said else 0.0

    def _decide(self, t: float) -> list[Decision | FusionState]:
        assert self.net is not None
        scene, top, pooled = self._leading(t)
        if scene is None or top < self.net.threshold_ or not self.net.said_enough(pooled):
            return [self.state(t)]
        decision = Decision(
            t,
            scene,
            100.0 * top,
            scene_line(scene),
            self._latest_confidence("audio"),
            self._latest_confidence("image"),
            confidence_unit="%",
            leaned_on=leaned_on(self.net, pooled, scene),
        )
        self._restart()
        return [decision, self.state(t)]

    def on_acoustic(
        self,
        scene: str | None,
        confidence: float,
        t: float,
        *,
        scores: Mapping[str, float] | None = None,
    ) -> list[Decision | FusionState]:
        return self.on_sense("audio", scene, confidence, t, scores)

    def on_visual(
        self,
        scene: str | None,
        confidence: float,
        t: float,
        *,
        scores: Mapping[str, float] | None = None,
    ) -> list[Decision | FusionState]:
        return self.on_sense("image", scene, confidence, t, scores)

    def wants_picture(self, t: float) -> bool:
        """Always looking, as the parallel policy: a picture every `picture_interval_s`."""
        if self.fallback is not None:
            return self.fallback.wants_picture(t)
        return (
            self.last_picture_at is None
            or t - self.last_picture_at >= self.config.picture_interval_s
        )
