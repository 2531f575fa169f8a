"""The paper's sequential fusion: hear first, then look, ignoring acoustic predictions meanwhile.

An acoustic prediction opens a window of `acoustic_window_s` (30 s), with a picture every
`picture_interval_s`. When `pictures_needed` visual predictions agreeing with it fall within
`confirm_window_s` (20 s) of each other, it says `<Scene>Scene detected` with the average of the
acoustic confidence and the mean confidence of the confirming pictures; if the window closes
first, `No scene detected` (confidence 0.000), and it starts listening again.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

from servant_core.choices import FusionConfig
from servant_core.events import Decision, FusionState
from servant_core.recognisers.base import UNKNOWN

NO_SCENE = "No scene detected"


def scene_line(scene: str | None) -> str:
    """The paper's terminal line: "coffee" → "CoffeeScene detected"; None → "No scene detected"."""
    if scene is None:
        return NO_SCENE
    words = scene.replace("-", " ").replace("_", " ").split()
    return "".join(w[:1].upper() + w[1:] for w in words) + "Scene detected"


class AcousticWindow(ABC):
    """What both policies share: the first acoustic opinion since the last decision opens a window
    of `acoustic_window_s`; if it closes undecided, the policy says `No scene detected` and starts
    afresh. A policy sets `config`; its `_restart` sets `opened_at` and `acoustic_confidence`."""

    config: FusionConfig
    opened_at: float | None
    acoustic_confidence: float
    # what a policy can hear (`fusion.pipeline.DecisionPipeline.tell`): any sense's opinion with
    # its scores (`on_sense`), and the sound's and pictures' scores (`scores=`) as evidence once
    # the sound knows somewhere else
    hears_every_sense: ClassVar[bool] = False
    weighs_scores: ClassVar[bool] = False

    @abstractmethod
    def _restart(self) -> None: ...

    @abstractmethod
    def state(self, t: float) -> FusionState: ...

    def seconds_left(self, t: float) -> float | None:
        if self.opened_at is None:
            return None
        return max(0.0, self.opened_at + self.config.acoustic_window_s - t)

    def tick(self, t: float) -> list[Decision | FusionState]:
        """Close the window if its time is up: `No scene detected`, and listen again."""
        if self.opened_at is None or t - self.opened_at <= self.config.acoustic_window_s:
            return []
        decision = Decision(t, None, 0.0, NO_SCENE, self.acoustic_confidence, 0.0)
        self._restart()
        return [decision, self.state(t)]


class SequentialFusion(AcousticWindow):
    def __init__(self, config: FusionConfig | None = None) -> None:
        self.config = config or FusionConfig()
        self._restart()

    def _restart(self) -> None:
        self.scene: str | None = None
        self.opened_at: float | None = None
        self.acoustic_confidence = 0.0
        self.matches: list[tuple[float, float]] = []  # (time, confidence) of agreeing pictures
        self.pictures_taken = 0
        self.last_picture_at: float | None = None

    @property
    def phase(self) -> str:
        if self.opened_at is None:
            return "listening"
        return "confirming" if self.matches else "looking"

    def state(self, t: float) -> FusionState:
        return FusionState(t, self.phase, self.scene, self.seconds_left(t), self.pictures_taken)

    def on_acoustic(
        self, scene: str | None, confidence: float, t: float
    ) -> list[Decision | FusionState]:
        events = self.tick(t)
        if self.opened_at is not None or scene is None or scene == UNKNOWN:
            return events
        self.scene, self.opened_at, self.acoustic_confidence = scene, t, float(confidence)
        return [*events, self.state(t)]

    def on_visual(
        self, scene: str | None, confidence: float, t: float
    ) -> list[Decision | FusionState]:
        events = self.tick(t)
        if self.opened_at is None:
            return events  # a picture with no sound before it decides nothing
        self.pictures_taken += 1
        self.last_picture_at = t
        if scene == self.scene:
            window = self.config.confirm_window_s
            self.matches = [m for m in self.matches if t - m[0] <= window] + [
                (t, float(confidence))
            ]
            if len(self.matches) >= self.config.pictures_needed:
                visual = sum(c for _, c in self.matches) / len(self.matches)
                average = (self.acoustic_confidence + visual) / 2.0
                decision = Decision(
                    t, self.scene, average, scene_line(self.scene), self.acoustic_confidence, visual
                )
                self._restart()
                return [*events, decision, self.state(t)]
        return [*events, self.state(t)]

    def wants_picture(self, t: float) -> bool:
        if self.opened_at is None:
            return False
        return (
            self.last_picture_at is None
            or t - self.last_picture_at >= self.config.picture_interval_s
        )
