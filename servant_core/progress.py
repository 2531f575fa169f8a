"""Progress of a long step on stderr: a bar with a count and an estimate of the time left.

`Progress` is an `on_progress(done, total)` callback (the one `servant_core.library` calls after
each file), so any front end can pass its own instead. On a terminal it redraws one line;
anywhere else (a pipe, a log file, a test) it stays silent, so output that is read by programs
is never mixed with bars.
"""

from __future__ import annotations

import shutil
import sys
import time
from collections.abc import Callable
from typing import TextIO

BAR_WIDTH = 24


def bar_line(label: str, done: int, total: int, elapsed: float, columns: int = 0) -> str:
    """`label [#######.....] 12/40  0:35 left` (pure: the estimate assumes a steady pace).
    With `columns`, the bar narrows (down to 5) so that the line fits in one row less a
    column: a line as wide as the terminal wraps, and each redraw would add a row."""
    total = max(total, 1)
    done = min(max(done, 0), total)
    if done == total:
        tail = f"done in {_clock(elapsed)}"
    elif done == 0:
        tail = ""
    else:
        tail = f"{_clock(elapsed / done * (total - done))} left"
    rest = f" {done}/{total}  {tail}".rstrip()
    width = BAR_WIDTH
    if columns:
        width = min(BAR_WIDTH, max(columns - 1 - len(label) - 3 - len(rest), 5))
    filled = width * done // total
    bar = "#" * filled + "." * (width - filled)
    line = f"{label} [{bar}]{rest}"
    return line[: columns - 1] if columns else line


def _clock(seconds: float) -> str:
    minutes, secs = divmod(int(round(seconds)), 60)
    hours, minutes = divmod(minutes, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


class Progress:
    """A bar for one step; call it as `on_progress(done, total)`.

    It draws only when `stream` is a terminal; redraws at most `interval` seconds apart (and at
    the end), and ends its line when the step is done.
    """

    def __init__(
        self,
        label: str,
        stream: TextIO | None = None,
        interval: float = 0.2,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.interval = interval
        self.clock = clock
        self.started = clock()
        self.drawn_at = -float("inf")
        self.enabled = bool(getattr(self.stream, "isatty", lambda: False)())

    def __call__(self, done: int, total: int) -> None:
        now = self.clock()
        if done <= 0:  # the work begins now (what came before, loading modules, is not its pace)
            self.started = now
        if not self.enabled:
            return
        finished = done >= total
        if not finished and now - self.drawn_at < self.interval:
            return
        self.drawn_at = now
        columns = shutil.get_terminal_size().columns
        line = bar_line(self.label, done, total, now - self.started, columns)
        self.stream.write("\r\x1b[K" + line + ("\n" if finished else ""))
        self.stream.flush()
