"""Words for events that every front end shares: the headless CLI's lines, the TUI's log and panes.

Each front end words an event its own way (the CLI in plain past-tense lines beside the paper's
terminal lines, the TUI shorter, for a narrow pane, in colour), but a predicted place and a
confidence read the same everywhere. A confidence is shown with what it is: "%" only when the
recogniser says it is a probability in percent; the paper's eq. 1 and eq. 2 are no percentages
(on real audio eq. 1 is often thousands below zero).
"""

from __future__ import annotations

UNKNOWN_PLACE = "an unknown place"


def place(scene: str | None) -> str:
    """A predicted scene in words: its name, or "an unknown place" (None, the open set)."""
    return scene or UNKNOWN_PLACE


def confidence_text(confidence: float, unit: str | None, width: int = 0) -> str:
    """The confidence and its unit ("88.0 %", "-6434.0 eq. 1"), or the bare number when the unit
    is not known; the number is right-aligned in at least `width` characters."""
    number = f"{confidence:{width}.1f}"
    return f"{number} {unit}" if unit else number
