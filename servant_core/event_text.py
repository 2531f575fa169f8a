"""Words for events that every front end shares: the headless CLI's lines and the TUI's log.

Each front end words an event its own way (the CLI in plain past-tense lines beside the paper's
terminal lines, the TUI shorter, for a narrow pane, in colour), but a predicted place reads the
same everywhere.
"""

from __future__ import annotations

UNKNOWN_PLACE = "an unknown place"


def place(scene: str | None) -> str:
    """A predicted scene in words: its name, or "an unknown place" (None, the open set)."""
    return scene or UNKNOWN_PLACE
