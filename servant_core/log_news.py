"""Which of the engine's events a log says, for every front end: `servant run --headless`'s
lines and the TUI's log both ask a `LogNews`, so that they cannot disagree.

A state that holds is said when it begins, not at every window it holds. What the events leave
unsaid is said too: leaving the place decided when the sound stops naming a place (`No scene
detected`, once), and whether that was for silence. Each front end words events its own way
(`event_text` holds the shared words).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from servant_core.events import AcousticPrediction, ArmState, Decision


@dataclass(frozen=True)
class News:
    """What a log says for one event."""

    said: bool  # the event's own line
    silent: bool = False  # the event is the sound's prediction of a silent window
    left: str | None = None  # the place decided that the sound no longer names: said once


class LogNews:
    """Call it with each event, in order, from one thread at a time: the `News` of the event.

    Every event is said but a `Decision` of the place last said (a first one, even `No scene
    detected`, is said) and an `ArmState` that holds: not moved to a place's pose, nor connected,
    lost, armed or disarmed since the last one said. An `AcousticPrediction` of no place right after
    one of a place, while a place is decided, also says that place `left`; that counts as the
    decision none (a policy's own `No scene detected` after it is not said again)."""

    def __init__(self) -> None:
        self._decided: tuple[str | None, ...] = ()  # the last decision said: (scene,)
        self._heard: str | None = None  # the place the sound's last window named
        self._arm: tuple[bool, bool] | None = None  # (connected, armed) last said

    def __call__(self, event: Any) -> News:
        if isinstance(event, Decision):
            if self._decided == (event.scene,):
                return News(False)
            self._decided = (event.scene,)
            return News(True)
        if isinstance(event, ArmState):
            state = (event.connected, event.armed)
            if event.pose_of is None and state == self._arm:
                return News(False)
            self._arm = state
            return News(True)
        if isinstance(event, AcousticPrediction):
            before, self._heard = self._heard, event.scene
            silent = event.silent
            decided = self._decided[0] if self._decided else None
            if event.scene is None and before is not None and decided is not None:
                self._decided = (None,)
                return News(True, silent, decided)
            return News(True, silent)
        return News(True)
