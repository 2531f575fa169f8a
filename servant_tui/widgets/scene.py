"""The scene pane: what each sense says, where the fusion stands, and the decisions so far."""

from __future__ import annotations

from collections import deque

from rich.table import Table
from rich.text import Text
from textual.widgets import Static

from servant_core.event_text import confidence_text
from servant_core.events import AcousticPrediction, Decision, FusionState, VisualPrediction
from servant_tui.widgets.text import bar, clock

HISTORY = 5
# A sense's row: the scene, then its confidence ending at this column when the scene leaves room
# (a percentage always does; the paper's eq. 1, often thousands below zero, may not).
PREDICTION_WIDTH = 20


class ScenePane(Static):
    DEFAULT_CSS = """
    ScenePane { height: 1fr; }
    """

    def __init__(self, *, confirm_window_s: float = 30.0, id: str | None = None) -> None:
        super().__init__(id=id)
        self.confirm_window_s = confirm_window_s
        self.heard: AcousticPrediction | None = None
        self.seen: VisualPrediction | None = None
        self.fusion: FusionState | None = None
        self.decisions: deque[Decision] = deque(maxlen=HISTORY)

    def on_mount(self) -> None:
        self.update(self._render_state())

    def show_event(self, event: object) -> None:
        if isinstance(event, AcousticPrediction):
            self.heard = event
        elif isinstance(event, VisualPrediction):
            self.seen = event
        elif isinstance(event, FusionState):
            self.fusion = event
        elif isinstance(event, Decision):
            self.decisions.appendleft(event)
        else:
            return
        self.update(self._render_state())

    def _render_state(self) -> Table:
        table = Table.grid(padding=(0, 1))
        table.add_column(style="bold", no_wrap=True, min_width=8)
        table.add_column(no_wrap=True)
        for name, prediction in (("hears", self.heard), ("sees", self.seen)):
            if prediction is None:
                table.add_row(name, Text("–", "grey50"))
            else:
                scene = prediction.scene or "unknown place"
                confidence = confidence_text(
                    prediction.confidence, prediction.confidence_unit, width=5
                )
                pad = max(len(scene) + 1, PREDICTION_WIDTH - len(confidence))
                table.add_row(name, Text.assemble((scene.ljust(pad), "cyan"), confidence))
        table.add_row("fusion", self._fusion_text())
        table.add_row("window", self._window_text())
        pictures = self.fusion.pictures_taken if self.fusion else 0
        table.add_row("pictures", str(pictures))
        last = self.decisions[0] if self.decisions else None
        if last is None:
            table.add_row("decided", Text("nothing yet", "grey50"))
        else:
            style = "bold green" if last.scene else "yellow"
            table.add_row("decided", Text(last.line, style))
            average = confidence_text(last.confidence, last.confidence_unit)
            table.add_row("", f"average {average}")
        for decision in list(self.decisions)[1:]:
            table.add_row(
                Text(clock(decision.t), "grey50"),
                Text(f"{decision.scene or '—':<14}{decision.confidence:5.1f}", "grey70"),
            )
        return table

    def _fusion_text(self) -> Text:
        if self.fusion is None:
            return Text("–", "grey50")
        state = self.fusion
        if not state.scene:
            return Text(state.phase, "magenta")
        # the space ends the styled run: a reader trimming runs keeps the words apart
        return Text.assemble((f"{state.phase} ", "magenta"), (state.scene, "cyan"))

    def _window_text(self) -> Text:
        state = self.fusion
        if state is None or state.seconds_left is None:
            return Text("closed", "grey50")
        fraction = state.seconds_left / self.confirm_window_s if self.confirm_window_s else 0.0
        return Text.assemble(bar(fraction, 10, "magenta"), f" {state.seconds_left:4.1f} s")
