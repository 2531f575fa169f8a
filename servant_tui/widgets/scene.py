"""The scene pane: what each sense says, where the fusion stands, and the decisions so far."""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

from rich.table import Table
from rich.text import Text
from textual.widgets import Static

from servant_core.event_text import SILENCE, UNKNOWN_PLACE, confidence_text, left_text
from servant_core.events import (
    AcousticPrediction,
    Decision,
    FusionState,
    SensePrediction,
    UnknownScene,
    VisualPrediction,
)
from servant_core.fusion.sequential import NO_SCENE
from servant_core.log_news import LogNews
from servant_core.senses import SAMPLE_SENSES
from servant_tui.widgets.text import bar, clock

HISTORY = 5
# A sense's row: the scene, then its confidence ending at this column when the scene leaves room
# (a percentage always does; the paper's eq. 1, often thousands below zero, may not).
PREDICTION_WIDTH = 20
# Rows a short pane leaves out, first to go first (the decisions' history goes before them): a
# pane at 80x24 with motion and ambient keeps what each sense says and what was decided.
OPTIONAL_ROWS = ("pictures", "window", "average")
# How a decision names the senses it leaned on; a sample sense by its own name
SENSE_WORDS = {"audio": "sound", "image": "pictures"}


def sense_words(senses: Sequence[str]) -> str:
    """ "sound, motion": senses by the words the panes use for them."""
    return ", ".join(SENSE_WORDS.get(s, s) for s in senses)


def leaned_text(decision: Decision) -> str | None:
    """ "leaned on sound, motion": the senses a learned fusion leaned on; None for the rule
    policies, whose decisions do not say."""
    leaned = decision.leaned_on
    return f"leaned on {sense_words(leaned)}" if leaned else None


def heard_by(event: object, sense: str) -> bool:
    """Whether an event is what `sense` makes of its latest window or picture (a taught place or
    none)."""
    return (
        (isinstance(event, AcousticPrediction) and sense == "audio")
        or (isinstance(event, VisualPrediction) and sense == "image")
        or (isinstance(event, SensePrediction) and sense == event.sense)
    )


def answers_question(event: object, sense: str) -> bool:
    """Whether an event says the place is known now, where "What is this place?" was asked for
    `sense`: a place is decided, or that sense names a taught place."""
    if not getattr(event, "scene", None):
        return False
    return isinstance(event, Decision) or heard_by(event, sense)


class ScenePane(Static):
    DEFAULT_CSS = """
    ScenePane { height: 1fr; }
    """

    def __init__(
        self,
        *,
        confirm_window_s: float = 30.0,
        sample_senses: Sequence[str] = (),
        id: str | None = None,
    ) -> None:
        super().__init__(id=id)
        self.confirm_window_s = confirm_window_s
        self.heard: AcousticPrediction | None = None
        self.seen: VisualPrediction | None = None
        # a row for each sample sense in use, or heard from
        self.felt: dict[str, SensePrediction | None] = {
            s: None for s in SAMPLE_SENSES if s in sample_senses
        }
        self.fusion: FusionState | None = None
        self.decisions: deque[Decision] = deque(maxlen=HISTORY)
        # "What is this place?" asked since the last decision: the wearer is somewhere untaught,
        # so the last decision is history, not where the wearer is
        self.asked: UnknownScene | None = None
        # the wearer said "Not now" (or pressed Escape): no question until this time (engine s)
        self.quiet_until: float | None = None
        # the question was answered (the sense names a taught place again) and nothing has been
        # decided since: the last decision was made before the wearer left, so it stays history
        self.deciding = False
        # the log's rule for leaving (`LogNews`): the sound stopped naming the place decided, so
        # that decision is history until the next one; what the log said of it, for the pane
        self.news = LogNews()
        self.left: str | None = None

    def on_mount(self) -> None:
        self.update(self._render_state(), layout=False)

    def on_resize(self) -> None:
        self.update(self._render_state(), layout=False)

    def show_event(self, event: object) -> None:
        if self.asked is not None and answers_question(event, self.asked.sense):
            self.asked = None
            self.deciding = True
            self.left = None
        news = self.news(event)
        if news.left is not None:
            self.left = left_text(news.left, news.silent)
        if isinstance(event, AcousticPrediction):
            self.heard = event
        elif isinstance(event, VisualPrediction):
            self.seen = event
        elif isinstance(event, SensePrediction):
            self.felt[event.sense] = event
        elif isinstance(event, FusionState):
            self.fusion = event
        elif isinstance(event, Decision):
            self.decisions.appendleft(event)
            self.deciding = False
            if event.scene:  # a place decided again; a policy's own "none" keeps why it left
                self.left = None
        elif isinstance(event, UnknownScene):
            self.asked = event
        else:
            return
        self.update(self._render_state(), layout=False)

    def not_now(self, until: float) -> None:
        """The wearer put the question off: the pane says so, and until when, not "asked"."""
        self.quiet_until = until
        self.update(self._render_state(), layout=False)

    def _question_text(self) -> str:
        asked = self.asked
        if asked is not None and self.quiet_until is not None and asked.t < self.quiet_until:
            return f"Not now: not asking again before {clock(self.quiet_until)}"
        return "asked what it is"

    def _render_state(self) -> Table:
        rows = self._rows()
        height = self.size.height
        if height:  # before the first layout there is no height to fit yet
            for optional in ("history", *OPTIONAL_ROWS):
                while len(rows) > height and any(key == optional for key, *_ in rows):
                    last = max(i for i, (key, *_) in enumerate(rows) if key == optional)
                    del rows[last]
        table = Table.grid(padding=(0, 1))
        table.add_column(style="bold", no_wrap=True, min_width=8)
        table.add_column(no_wrap=True)
        for _, label, text in rows:
            table.add_row(label, text)
        return table

    def _rows(self) -> list[tuple[str, Text | str, Text | str]]:
        """(key, label, text) of each row: the key says which rows a short pane may drop."""
        rows: list[tuple[str, Text | str, Text | str]] = []
        senses = (("hears", self.heard), ("sees", self.seen), *self.felt.items())
        for name, prediction in senses:
            silent = isinstance(prediction, AcousticPrediction) and prediction.silent
            rows.append(("sense", name, self._prediction_text(prediction, silent)))
        rows.append(("fusion", "fusion", self._fusion_text()))
        rows.append(("window", "window", self._window_text()))
        pictures = self.fusion.pictures_taken if self.fusion else 0
        rows.append(("pictures", "pictures", str(pictures)))
        last = self.decisions[0] if self.decisions else None
        history = list(self.decisions)[1:]
        if self.asked is not None:
            # an untaught place: its question, and the last decision goes to the history
            rows.append(("decided", "decided", Text(UNKNOWN_PLACE, "magenta")))
            rows.append(("average", "", Text(self._question_text(), "magenta")))
            history = list(self.decisions)
        elif self.left is not None:
            # the sound no longer names the place decided: it goes to the history, as in the log
            rows.append(("decided", "decided", Text(NO_SCENE, "yellow")))
            rows.append(("average", "", Text(self.left, "yellow")))
            history = [d for d in self.decisions if d.scene]
        elif last is None or self.deciding:
            rows.append(
                ("decided", "decided", Text("deciding…" if last else "nothing yet", "grey50"))
            )
            history = list(self.decisions)
        else:
            style = "bold green" if last.scene else "yellow"
            rows.append(("decided", "decided", Text(last.line, style)))
            figure = confidence_text(last.confidence, last.confidence_unit)
            # the probability of this place and not elsewhere, or the senses' average
            said = "here, not elsewhere" if last.not_elsewhere else "average"
            rows.append(("average", "", f"{said} {figure}"))
            if last.leaned_on:
                # "leaned on …" across the columns: the line is too narrow for it after a blank
                on = sense_words(last.leaned_on)
                rows.append(("leaned", "leaned", Text(f"on {on}", "green")))
        for decision in history:
            rows.append(
                (
                    "history",
                    Text(clock(decision.t), "grey50"),
                    Text(f"{decision.scene or '—':<14}{decision.confidence:5.1f}", "grey70"),
                )
            )
        return rows

    @staticmethod
    def _prediction_text(
        prediction: AcousticPrediction | VisualPrediction | SensePrediction | None,
        silent: bool = False,
    ) -> Text:
        if prediction is None:
            return Text("–", "grey50")
        if prediction.scene is None:  # a confidence in no scene says nothing
            return Text(SILENCE if silent else "unknown place", "yellow")
        scene = prediction.scene
        confidence = confidence_text(prediction.confidence, prediction.confidence_unit, width=5)
        pad = max(len(scene) + 1, PREDICTION_WIDTH - len(confidence))
        return Text.assemble((scene.ljust(pad), "cyan"), confidence)

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
