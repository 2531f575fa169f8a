"""Parallel fusion (the paper's future work): hear and look at the same time.

Pictures are taken every `picture_interval_s`; each window's sound prediction replaces the last. A
scene is decided once the latest sound names it with `min_acoustic_confidence` and it leads the
last `confirm_window_s`'s picture votes with at least `votes_needed` (unknown pictures do not vote).
When the sound knows somewhere else (`scores=`), the scene is decided once
`fusion.elsewhere.place_probability` of the sound and those pictures reaches `OPEN_DECIDE_AT`. With
no agreement within `acoustic_window_s`, it says `No scene detected`, forgets and goes on."""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping

from servant_core.events import Decision, FusionState
from servant_core.fusion.elsewhere import OPEN_DECIDE_AT, place_probability
from servant_core.fusion.sequential import AcousticWindow, FusionConfig, scene_line
from servant_core.recognisers.base import UNKNOWN


class ParallelFusion(AcousticWindow):
    weighs_scores = True

    def __init__(
        self,
        config: FusionConfig | None = None,
        *,
        votes_needed: int = 2,
        min_acoustic_confidence: float = 0.0,
    ) -> None:
        self.config = config or FusionConfig()
        self.votes_needed = votes_needed
        self.min_acoustic_confidence = min_acoustic_confidence
        self.last_picture_at: float | None = None
        self._restart()

    def _restart(self) -> None:
        self.scene: str | None = None  # the latest acoustic opinion
        self.acoustic_confidence = 0.0
        self.opened_at: float | None = None  # first acoustic opinion since the last decision
        self.pictures: list[tuple[float, str, float]] = []  # (time, scene, confidence)
        # the sound's probabilities when it knows somewhere else, and the pictures' shares
        self.sound_scores: Mapping[str, float] | None = None
        self.picture_scores: list[tuple[float, Mapping[str, float]]] = []

    def _recent(self, t: float) -> list[tuple[float, str, float]]:
        window = self.config.confirm_window_s
        return [p for p in self.pictures if t - p[0] <= window]

    def _agreeing(self, t: float) -> list[float]:
        """Confidences of recent pictures naming the acoustic scene, if it leads the vote."""
        recent = self._recent(t)
        votes = Counter(scene for _, scene, _ in recent)
        if self.scene is None or votes[self.scene] < self.votes_needed:
            return []
        if any(n >= votes[self.scene] for s, n in votes.items() if s != self.scene):
            return []
        return [c for _, scene, c in recent if scene == self.scene]

    @property
    def phase(self) -> str:
        if self.scene is None:
            return "listening"
        return "confirming" if any(s == self.scene for _, s, _ in self.pictures) else "looking"

    def state(self, t: float) -> FusionState:
        return FusionState(t, self.phase, self.scene, self.seconds_left(t), len(self._recent(t)))

    def _decide_open(self, t: float) -> list[Decision | FusionState]:
        """Decide on the probability of the sound's place and not somewhere else, from the
        sound and the recent pictures' average shares (module docstring)."""
        window = self.config.confirm_window_s
        seen = [scores for when, scores in self.picture_scores if t - when <= window]
        if self.scene is None or self.sound_scores is None or len(seen) < self.votes_needed:
            return [self.state(t)]
        places = set().union(*seen)
        pooled = {p: sum(s.get(p, 0.0) for s in seen) / len(seen) for p in places}
        scores = {"acoustic": self.sound_scores, "visual": pooled}
        sure = place_probability(self.scene, scores, ("acoustic", "visual"), {"acoustic"})
        if sure < OPEN_DECIDE_AT:
            return [self.state(t)]
        decision = Decision(
            t,
            self.scene,
            100.0 * sure,
            scene_line(self.scene),
            self.acoustic_confidence,
            100.0 * pooled.get(self.scene, 0.0),
            not_elsewhere=True,
        )
        self._restart()
        return [decision, self.state(t)]

    def _decide(self, t: float) -> list[Decision | FusionState]:
        if self.sound_scores is not None:
            return self._decide_open(t)
        agreeing = self._agreeing(t)
        if not agreeing or self.acoustic_confidence < self.min_acoustic_confidence:
            return [self.state(t)]
        visual = sum(agreeing) / len(agreeing)
        scene = self.scene
        decision = Decision(
            t,
            scene,
            (self.acoustic_confidence + visual) / 2.0,
            scene_line(scene),
            self.acoustic_confidence,
            visual,
        )
        self._restart()
        return [decision, self.state(t)]

    def tick(self, t: float) -> list[Decision | FusionState]:
        """Forget pictures older than `confirm_window_s`; give up on the current opinion once
        `acoustic_window_s` has passed without agreement."""
        self.pictures = self._recent(t)
        window = self.config.confirm_window_s
        self.picture_scores = [p for p in self.picture_scores if t - p[0] <= window]
        return super().tick(t)

    def on_acoustic(
        self,
        scene: str | None,
        confidence: float,
        t: float,
        *,
        scores: Mapping[str, float] | None = None,
    ) -> list[Decision | FusionState]:
        """The latest window's opinion; `scores` only when the sound knows somewhere else (its
        probabilities of the taught places and not elsewhere)."""
        events = self.tick(t)
        if scene is None or scene == UNKNOWN:
            self.scene, self.acoustic_confidence = None, 0.0
            return [*events, self.state(t)]
        self.scene, self.acoustic_confidence = scene, float(confidence)
        self.sound_scores = dict(scores) if scores is not None else None
        if self.opened_at is None:
            self.opened_at = t
        return [*events, *self._decide(t)]

    def on_visual(
        self,
        scene: str | None,
        confidence: float,
        t: float,
        *,
        scores: Mapping[str, float] | None = None,
    ) -> list[Decision | FusionState]:
        """A picture's opinion; `scores`, its shares among the taught places, are its evidence
        when the sound knows somewhere else."""
        events = self.tick(t)
        self.last_picture_at = t
        if scores:
            self.picture_scores.append((t, dict(scores)))
        if scene is not None and scene != UNKNOWN:
            self.pictures.append((t, scene, float(confidence)))
        return [*events, *self._decide(t)]

    def wants_picture(self, t: float) -> bool:
        """Always looking: a picture every `picture_interval_s`, whatever the sound says."""
        return (
            self.last_picture_at is None
            or t - self.last_picture_at >= self.config.picture_interval_s
        )
