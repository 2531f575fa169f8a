"""What the steps of teach mode share: a pane of the wizard, and its workers' failures said."""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar, cast

from rich.text import Text
from textual import getters
from textual.containers import Vertical
from textual.widgets import Button, ContentSwitcher, Static
from textual.worker import Worker, WorkerState

from servant_core.errors import ServantError
from servant_tui.widgets.text import error_text

if TYPE_CHECKING:
    from servant_tui.app import ServantApp
    from servant_tui.screens.teach.screen import TeachScreen

T = TypeVar("T")


def every_press(button: Button) -> Button:
    """`button`, each press of which counts. Textual ignores a press within its press animation
    (0.2 s, ended by a timer): two quick Enters on *Take picture* took one picture, and on a
    loaded machine, where the timer ran late, a press after the first picture was on the screen
    was lost."""
    button.active_effect_duration = 0
    return button


class TeachStep(Vertical):
    """A step of teach mode, shown by the wizard's switcher under its id (`screen.STEPS`). A
    worker of the step that fails is reported (log and notification) and said in the step's
    status line, `STATUS`. Textual tells only the widget that started a worker how it ended."""

    STATUS = ""  # the Static where the step's work says how it went; none when empty

    if TYPE_CHECKING:
        app = getters.app(ServantApp)

    @property
    def wizard(self) -> TeachScreen:
        """Teach mode's screen: the scene taught, the steps' navigation, the arm's joints."""
        return cast("TeachScreen", self.screen)

    def shown(self) -> bool:
        """Whether this step is the one the wizard shows."""
        switcher = self.parent
        return isinstance(switcher, ContentSwitcher) and switcher.current == self.id

    def start_again(self) -> None:
        """Forget what this step knew of the scene taught: another scene is next."""

    def attempt(self, step: Callable[[], T]) -> T | None:
        """`step()`, or None when it raised a ServantError, which is reported."""
        try:
            return step()
        except ServantError as error:
            self.app.report_error(error)
            return None

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.state == WorkerState.ERROR and event.worker.error is not None:
            self.app.report_error(event.worker.error)
            self.work_failed(event.worker.group, event.worker.error)

    def work_failed(self, group: str, error: BaseException) -> None:
        if self.STATUS:
            self.query_one(self.STATUS, Static).update(
                Text.assemble((f"{group} failed: ", "bold red"), error_text(error))
            )
