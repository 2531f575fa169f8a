"""Step 5 of teach mode: the action learner trained on every teach record, its error falling as
it goes; the recognisers retrained on the scene library."""

from __future__ import annotations

from typing import Any

from textual import on, work
from textual.app import ComposeResult
from textual.containers import Horizontal
from textual.widgets import Button, Label, ProgressBar, Sparkline, Static

from servant_core.engine.learning import retrained_text
from servant_core.library import SceneLibrary
from servant_tui.messages import RetrainDone, TrainingDone, TrainingProgress
from servant_tui.screens.secondary import with_progress
from servant_tui.screens.teach.step import TeachStep
from servant_tui.widgets.progress import OnProgress, WorkProgress


class TrainStep(TeachStep):
    """*Train* fits the scene → pose learner; *Retrain recognisers* refits sound and pictures."""

    STATUS = "#train-status"

    def __init__(self, *, id: str) -> None:
        super().__init__(id=id)
        self.errors: list[float] = []  # the training's mean error so far, in degrees

    def compose(self) -> ComposeResult:
        yield Label("Learn scene → pose from every teach record; retrain the recognisers.")
        with Horizontal(classes="buttons"):
            yield Button("Train", id="train-learner", variant="primary")
            yield Button("Retrain recognisers", id="retrain")
        # empty until Train is pressed: a bar of unknown length would animate as if a job were
        # running
        yield ProgressBar(total=1, show_eta=False, id="train-progress")
        yield WorkProgress(id="retrain-progress")
        yield Sparkline([], id="error-curve")
        yield Static(id="train-status")

    def on_mount(self) -> None:
        self.query_one("#error-curve").border_title = "training error (degrees)"

    @on(Button.Pressed, "#train-learner")
    def start_training(self) -> None:
        self.errors = []
        self.query_one("#train-learner", Button).disabled = True
        self.train(self.wizard.settings())

    @work(thread=True, exclusive=True, group="train", exit_on_error=False)
    def train(self, settings: Any) -> None:
        from servant_core.actions.learner import ActionLearner
        from servant_core.actions.records import load_records

        try:
            records = load_records()
            # a record that sets only some joints (e.g. `servant teach` with one angle) leaves
            # the others at their home angle, as the CLI does
            options = (
                {}
                if settings is None
                else {
                    "home": {j.name: j.home_angle for j in settings.joints},
                    "confidence_threshold": settings.confidence_threshold,
                }
            )
            learner = ActionLearner(report_every=100, **options)  # 100: points for a curve
            total = learner.max_iter

            def report(iterations: int, error: float) -> None:
                self.post_message(TrainingProgress(iterations, total, error))

            learner.fit(records, report=report)
            learner.save()
        finally:
            self.app.call_from_thread(self._training_over)
        self.post_message(TrainingDone(learner))

    def _training_over(self) -> None:
        self.query_one("#train-learner", Button).disabled = False

    @on(TrainingProgress)
    def training_progress(self, message: TrainingProgress) -> None:
        self.errors.append(message.error)
        self.query_one("#train-progress", ProgressBar).update(
            total=message.total, progress=message.step
        )
        self.query_one("#error-curve", Sparkline).data = list(self.errors)
        self.query_one("#train-status", Static).update(
            f"iteration {message.step}/{message.total}: mean error {message.error:.2f}°"
        )

    @on(TrainingDone)
    def trained(self, message: TrainingDone) -> None:
        self.wizard.learner = message.learner
        final = self.errors[-1] if self.errors else float("nan")
        summary = f"trained on {message.learner.n_records_} teach records; error {final:.2f}°"
        # README step 3 goes on with Retrain in this step: the focus goes there (jumping to the
        # Test step left Retrain a step back, out of Enter's reach); Test shows the poses
        self.query_one("#train-status", Static).update(
            f"{summary}. Next: Retrain recognisers; the poses are in the Test step."
        )
        self.app.log_line(None, summary)
        self.wizard.show_predictions()
        if self.shown():
            self.query_one("#retrain", Button).focus()

    @on(Button.Pressed, "#retrain")
    def start_retrain(self) -> None:
        self.query_one("#train-status", Static).update("retraining the recognisers…")
        self.retrain(self.query_one("#retrain-progress", WorkProgress).begin())

    @work(thread=True, exclusive=True, group="retrain", exit_on_error=False)
    def retrain(self, on_progress: OnProgress) -> None:
        library = SceneLibrary.scan(self.app.library_root)
        engine = self.app.engine
        senses = with_progress(
            engine.retrain, library, on_progress, reports=engine.retrain_reports_progress
        )
        self.post_message(RetrainDone(retrained_text(senses, library)))

    @on(RetrainDone)
    def retrained(self, message: RetrainDone) -> None:
        self.query_one("#retrain-progress", WorkProgress).end(finished=True)
        self.query_one("#train-status", Static).update(message.summary)
        self.app.log_line(None, message.summary)

    def work_failed(self, group: str, error: BaseException) -> None:
        if group == "retrain":
            self.query_one("#retrain-progress", WorkProgress).end(finished=False)
        super().work_failed(group, error)
