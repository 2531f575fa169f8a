"""Words for events that every front end shares: the headless CLI's lines, the TUI's log and panes.

Each front end words an event its own way (the CLI in plain past-tense lines beside the paper's
terminal lines, the TUI shorter, for a narrow pane, in colour), but a predicted place and a
confidence read the same everywhere. A confidence is shown with what it is: "%" only when the
recogniser says it is a probability in percent; the paper's eq. 1 and eq. 2 are no percentages
(on real audio eq. 1 is often thousands below zero).
"""

from __future__ import annotations

import math
from typing import Any

from servant_core.place_names import printable_name

UNKNOWN_PLACE = "an unknown place"
SILENCE = "silence"  # what a silent window is heard as: no place, and not an unknown one


def place(scene: str | None) -> str:
    """A predicted scene in words: its name, or "an unknown place" (None, the open set). A name
    from a folder made by hand may hold a newline: it is shown escaped, on the line."""
    return printable_name(scene) if scene else UNKNOWN_PLACE


def left_text(scene: str, silent: bool) -> str:
    """Why a place decided is no longer: "coffee no longer heard: silence" (`log_news.News`)."""
    return f"{place(scene)} no longer heard: {SILENCE if silent else UNKNOWN_PLACE}"


def confidence_text(confidence: float, unit: str | None, width: int = 0) -> str:
    """The confidence and its unit ("88.0 %", "-6434.0 eq. 1", "1.8× average": a factor keeps
    its ×), or the bare number when the unit is not known; the number is right-aligned in at
    least `width` characters."""
    number = f"{confidence:{width}.1f}"
    if not unit:
        return number
    return f"{number}{unit}" if unit.startswith("×") else f"{number} {unit}"


def angle_text(angle: float) -> str:
    """An angle in whole degrees ("20°", never "-0°": a whole number has no sign of zero); "—"
    for none (NaN). A servo's step is coarser than a degree, so decimals would only show the
    float arithmetic of the speed limits or a learner's rounding ("-0.0°" for 0°)."""
    return f"{round(angle):d}°" if math.isfinite(angle) else "—"


def pose_text(pose: dict[str, float]) -> str:
    """A pose in words, whole degrees ("shoulder 10°, elbow 20°"; see `angle_text`)."""
    return ", ".join(f"{joint} {angle_text(angle)}" for joint, angle in pose.items()) or "no joint"


def arm_text(state: Any) -> str:
    """An `ArmState` in words: the move it has just made, else whether it is armed."""
    if state.pose_of is not None:
        return f"arm moved to {state.pose_of}'s pose: {pose_text(state.angles)}"
    if not state.connected:
        return "arm not connected"
    if state.armed:
        return f"arm armed, at {pose_text(state.angles)}"
    return "arm disarmed"
