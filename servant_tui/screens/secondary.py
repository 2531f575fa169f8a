"""What the screens over the live one share: their workers' failures reach the user, progress
reaches a bar, and the keys that matter most come first in the footer.

Textual posts a worker's state changes to the widget that started it, and they do not bubble: a
screen that starts workers must handle them itself, or their errors vanish (the app only sees its
own workers).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

from textual import getters
from textual.binding import Binding
from textual.screen import Screen
from textual.worker import Worker, WorkerState

from servant_core.library import SceneLibrary
from servant_tui.heap import release_free_heap
from servant_tui.widgets.progress import OnProgress

if TYPE_CHECKING:
    from servant_tui.app import ServantApp

# The app's help and quit, listed again so a screen's footer shows them right after its own keys;
# the app's other keys work here too but are not listed (at 80 columns the footer has room for a
# handful), and help takes both its keys, or the app's f1 would list "? Help" a second time.
# The footer shows an action's first key that works where the focus is: `?` and `q`, and while
# the focus takes typed letters (a field; Textual leaves it the keys it consumes, and `q` typed
# a q into teach mode's name field while the footer said `q Quit`), f1 and ctrl+q. Ctrl+q has
# priority, as Textual's own has, which would otherwise take its place in the footer, unshown.
HELP_AND_QUIT = [
    Binding("question_mark", "app.help", "Help", key_display="?"),
    Binding("f1", "app.help", "Help"),
    Binding("q", "app.quit", "Quit"),
    Binding("ctrl+q", "app.quit", "Quit", priority=True),
    Binding("a", "app.toggle_arm", "Arm/Disarm", show=False),
    Binding("t", "app.teach", "Teach", show=False),
    Binding("l", "app.library", "Library", show=False),
    Binding("s", "app.settings", "Settings", show=False),
]


class ServantScreen(Screen[None]):
    """A screen of the `ServantApp`, which the type checker knows `self.app` to be (its engine,
    settings, log). For the type checker only: at run time `app` is Textual's own property, so a
    test may still show the screen in an app of its own."""

    if TYPE_CHECKING:
        app = getters.app(ServantApp)


class ReportsWorkerErrors(ServantScreen):
    """A screen whose workers' failures reach the user: a worker of group G that fails calls
    `work_failed(G, error)`, which says so in the screen (its status line) after the app has
    logged and notified it."""

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.state == WorkerState.ERROR and event.worker.error is not None:
            self.app.report_error(event.worker.error)
            self.work_failed(event.worker.group, event.worker.error)

    def work_failed(self, group: str, error: BaseException) -> None:
        """Show the failure where the job's progress was shown (override per screen)."""


class _Walked(list[Any]):
    """A list that reports how far it has been walked: the featurize loops walk a library's
    recordings (and pictures) once, in order, each step the cost of one file. Walking it again
    (e.g. `list(...)` of it afterwards) never moves the count back."""

    def __init__(self, items: list[Any], advance: Callable[[int], None]) -> None:
        super().__init__(items)
        self._advance = advance

    def __iter__(self) -> Iterator[Any]:
        for index, item in enumerate(super().__iter__()):
            self._advance(index)
            yield item


def walked_library(
    library: SceneLibrary, on_progress: OnProgress, pictures: bool = True
) -> SceneLibrary:
    """`library`, reporting `(files done, files)` as its recordings (then its pictures) are
    walked. Used while the engine's retrain and the evaluation take no `on_progress`."""
    total = len(library.recordings) + (len(library.pictures) if pictures else 0)
    done = [0]

    def advance_to(n: int) -> None:
        if n > done[0]:
            done[0] = n
            on_progress(n, total)

    on_progress(0, total)
    recordings = _Walked(library.recordings, advance_to)
    if not pictures:
        return dataclasses.replace(library, recordings=recordings)
    offset = len(library.recordings)
    walked = _Walked(library.pictures, lambda i: advance_to(offset + i))
    return dataclasses.replace(library, recordings=recordings, pictures=walked)


def with_progress(
    job: Callable[..., Any],
    library: SceneLibrary,
    on_progress: OnProgress,
    *,
    reports: bool,
    pictures: bool = True,
    **options: Any,
) -> Any:
    """`job(library, **options)` reporting its progress: through its own `on_progress` when it
    `reports` (takes one), else by counting the files it walks (`walked_library`)."""
    try:
        if reports:
            return job(library, on_progress=on_progress, **options)
        return job(walked_library(library, on_progress, pictures), **options)
    finally:
        release_free_heap()  # a retrain or an evaluation frees most of what it took
