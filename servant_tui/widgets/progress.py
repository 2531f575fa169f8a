"""Progress of a long job (retrain, evaluate): a bar with an estimate of the time left, fed by a
`(done, total)` callback that worker threads may call."""

from __future__ import annotations

from collections.abc import Callable

from textual.widgets import ProgressBar

OnProgress = Callable[[int, int], None]


class WorkProgress(ProgressBar):
    """Hidden until a job begins; `reporter()` hands the job a thread-safe `(done, total)`."""

    DEFAULT_CSS = """
    WorkProgress { display: none; height: 1; }
    WorkProgress.-running { display: block; }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(total=None, show_eta=True, id=id)

    def begin(self) -> OnProgress:
        """Show the bar (still unknown length) and return the callback a worker feeds it with."""
        self.update(total=None, progress=0)
        self.add_class("-running")
        app = self.app  # looked up here, on the UI thread

        def on_progress(done: int, total: int) -> None:
            app.call_from_thread(self.update, total=max(total, 1), progress=min(done, total))

        return on_progress

    def end(self, finished: bool) -> None:
        """A finished job leaves the bar full until the next one; a failed one hides it."""
        if finished:
            self.update(total=self.total or 1, progress=self.total or 1)
        else:
            self.remove_class("-running")
