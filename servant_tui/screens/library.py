"""The library screen: scenes, their recordings and pictures; relabel, delete, retrain, evaluate."""

from __future__ import annotations

import os
from pathlib import Path

from rich.markup import escape
from rich.table import Table
from textual import on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.widgets import DataTable, Footer, Header, Static

from servant_core.engine.learning import retrained_text
from servant_core.errors import ServantError
from servant_core.evaluate import TAUGHT, evaluate_audio
from servant_core.library import SceneLibrary
from servant_core.place_names import place_name, printable_name
from servant_core.recognisers import FRESH_METHODS
from servant_tui.messages import EvaluationDone, RetrainDone
from servant_tui.screens.dialogs import Confirm, ScenePrompt
from servant_tui.screens.secondary import HELP_AND_QUIT, ReportsWorkerErrors, with_progress
from servant_tui.widgets.progress import OnProgress, WorkProgress
from servant_tui.widgets.text import error_text, path_text


def free_path(folder: Path, name: str) -> Path:
    """`folder/name`, or `folder/stem-2.suffix` and so on if taken: nothing is overwritten."""
    candidate = folder / name
    stem, suffix = Path(name).stem, Path(name).suffix
    n = 2
    while candidate.exists():
        candidate = folder / f"{stem}-{n}{suffix}"
        n += 1
    return candidate


PROTOCOL_WORDS = {
    "temporal": "each recording's first 60 % teaching, the rest testing",
    "recording": "leaving one recording out at a time",
}


def evaluation_table(result: dict) -> Table:
    table = Table(title=f"{result['protocol']} protocol, {result['method']} method", expand=False)
    table.add_column("measure")
    table.add_column("value", justify="right")
    table.add_row("accuracy", f"{100 * result['accuracy']:.1f} %")
    table.add_row("balanced accuracy", f"{100 * result['balanced_accuracy']:.1f} %")
    for scene, recall in sorted(result["per_class"].items()):
        table.add_row(f"recall {scene}", f"{100 * recall:.1f} %")
    table.add_row("test windows", str(result["n_test"]))
    return table


class LibraryScreen(ReportsWorkerErrors):
    BINDINGS = [
        Binding("escape", "app.pop_screen", "Back"),
        Binding("d", "delete", "Delete"),
        Binding("r", "relabel", "Relabel"),
        Binding("R", "retrain", "Retrain"),
        Binding("e", "evaluate", "Evaluate"),
        # the tables' own home/end scroll without moving the selection that `d` and `r` act on
        Binding("home", "edge_row(0)", show=False, priority=True),
        Binding("end", "edge_row(-1)", show=False, priority=True),
        *HELP_AND_QUIT,
    ]

    def __init__(self) -> None:
        super().__init__()
        self.library: SceneLibrary | None = None
        self.scene: str | None = None
        self.evaluation: dict | None = None

    def compose(self) -> ComposeResult:
        yield Header()
        with Horizontal(id="library"):
            with Vertical(id="library-left"):
                yield DataTable(id="scenes", cursor_type="row")
                yield Static(id="evaluation")
            yield DataTable(id="samples", cursor_type="row")
        yield WorkProgress(id="library-progress")
        yield Static(id="library-status")
        yield Footer()

    def on_mount(self) -> None:
        self.query_one("#scenes").border_title = "Scenes"
        self.query_one("#samples").border_title = "Samples"
        self.query_one("#evaluation").border_title = "Evaluation"
        self.query_one("#scenes", DataTable).add_columns("scene", "recordings", "pictures")
        self.query_one("#samples", DataTable).add_columns("kind", "file", "kB")
        self.rescan()

    @property
    def root(self) -> Path:
        return self.app.library_root

    def status(self, text: str) -> None:
        self.query_one("#library-status", Static).update(text)

    def work_failed(self, group: str, error: BaseException) -> None:
        self.query_one(WorkProgress).end(finished=False)
        self.status(f"[red]{group} failed:[/] {escape(error_text(error))}")

    def rescan(self) -> None:
        scenes = self.query_one("#scenes", DataTable)
        scenes.clear()
        try:
            self.library = SceneLibrary.scan(self.root)
        except ServantError:
            self.library = SceneLibrary(self.root, [])
            self.status(f"{self.root}: empty — teach a scene (t) to start the library")
            self.show_samples(None)
            return
        for scene in self.library.scenes:
            n_recordings = sum(r.scene == scene for r in self.library.recordings)
            n_pictures = sum(p.scene == scene for p in self.library.pictures)
            scenes.add_row(scene, str(n_recordings), str(n_pictures), key=scene)
        self.status(f"{self.root}: {len(self.library.scenes)} scenes")
        if self.library.scenes:
            keep = self.scene if self.scene in self.library.scenes else self.library.scenes[0]
            scenes.move_cursor(row=self.library.scenes.index(keep))
            self.show_samples(keep)
        else:
            self.show_samples(None)

    @on(DataTable.RowHighlighted, "#scenes")
    def scene_chosen(self, event: DataTable.RowHighlighted) -> None:
        self.show_samples(event.row_key.value)

    def show_samples(self, scene: str | None) -> None:
        self.scene = scene
        samples = self.query_one("#samples", DataTable)
        samples.clear()
        if scene is None or self.library is None:
            return
        items = [("recording", r.path) for r in self.library.recordings if r.scene == scene]
        items += [("picture", p.path) for p in self.library.pictures if p.scene == scene]
        for kind, path in items:
            relative = path.relative_to(self.root / scene)
            samples.add_row(kind, str(relative), f"{path.stat().st_size / 1024:.0f}", key=str(path))

    def selected_sample(self) -> Path | None:
        samples = self.query_one("#samples", DataTable)
        if samples.row_count == 0:
            return None
        key = samples.coordinate_to_cell_key(samples.cursor_coordinate).row_key.value
        return None if key is None else Path(key)  # each row is keyed by its file's path

    def action_edge_row(self, which: int) -> None:
        """Home / End: the first or last row of the focused table, selected."""
        table = self.focused
        if isinstance(table, DataTable) and table.row_count:
            table.move_cursor(row=which % table.row_count)

    def action_delete(self) -> None:
        if self.focused is self.query_one("#scenes", DataTable):
            self.notify(
                "d deletes the recording or picture selected in Samples (Tab goes there). A "
                f"whole place is removed by deleting its folder, {self.root}/"
                f"{self.scene or '<scene>'}/, outside Servant",
                title="Library",
            )
            return
        path = self.selected_sample()
        if path is None:
            self.notify("This place has no recordings or pictures to delete.", title="Library")
            return

        def confirmed(yes: bool | None) -> None:
            if yes:
                try:
                    path.unlink(missing_ok=True)
                except OSError as error:
                    self.app.report_error(
                        ServantError(f"{path}: cannot delete ({error.strerror}); check its folder")
                    )
                    return
                self.app.log_line(None, f"deleted {path}")
                self.rescan()

        self.app.push_screen(Confirm(f"Delete {path.name} from {self.scene}?"), confirmed)

    def action_relabel(self) -> None:
        path = self.selected_sample()
        if path is None or self.library is None:
            return

        def relabelled(scene: str | None) -> None:
            if not scene:
                return
            try:
                scene = place_name(scene, self.root, self.library.scenes if self.library else [])
            except ServantError as error:
                self.app.report_error(error)
                return
            if scene == self.scene:
                return
            folder = self.root / scene
            try:
                folder.mkdir(parents=True, exist_ok=True)
                # same file system: the sample is in one place or the other
                os.replace(path, free_path(folder, path.name))
            except OSError as error:
                self.app.report_error(
                    ServantError(f"{path}: cannot move it to {scene} ({error.strerror})")
                )
                return
            name, before, after = map(printable_name, (path.name, self.scene or "", scene))
            self.app.log_line(None, escape(f"moved {name} from {before} to {after}"))
            self.rescan()

        self.app.push_screen(
            ScenePrompt(
                f"Relabel {path.name} as which scene?", self.library.scenes, self.scene or ""
            ),
            relabelled,
        )

    def action_retrain(self) -> None:
        self.status("retraining the recognisers…")
        self.retrain(self.query_one(WorkProgress).begin())

    @work(thread=True, exclusive=True, group="retrain", exit_on_error=False)
    def retrain(self, on_progress: OnProgress) -> None:
        library = SceneLibrary.scan(self.root)
        engine = self.app.engine
        senses = with_progress(
            engine.retrain, library, on_progress, reports=engine.retrain_reports_progress
        )
        saved = self.app.engine.model_path
        self.post_message(
            RetrainDone(
                retrained_text(senses, library)
                + (f"; model saved to {path_text(saved)}" if saved else "")
            )
        )

    @on(RetrainDone)
    def retrained(self, message: RetrainDone) -> None:
        self.query_one(WorkProgress).end(finished=True)
        self.status(message.summary)
        self.app.log_line(None, message.summary)

    def action_evaluate(self) -> None:
        self.status("evaluating the sound…")
        self.evaluate(self.query_one(WorkProgress).begin())

    @work(thread=True, exclusive=True, group="evaluate", exit_on_error=False)
    def evaluate(self, on_progress: OnProgress) -> None:
        library = SceneLibrary.scan(self.root)
        # the method the engine listens with (a first start: the one a retrain would fit)
        acoustic = self.app.engine.acoustic
        method = acoustic.method if acoustic is not None else None
        result = with_progress(
            evaluate_audio,
            library,
            on_progress,
            reports=True,
            pictures=False,
            method=method or FRESH_METHODS["audio"],
            protocol=TAUGHT,
            # the same bar, a second phase: a model fitted and tested per sample left out (the
            # listening is a moment; the bar sat full while every fold was fitted)
            on_fold=on_progress,
        )
        self.post_message(EvaluationDone(result))

    @on(EvaluationDone)
    def evaluated(self, message: EvaluationDone) -> None:
        self.evaluation = message.result
        self.query_one(WorkProgress).end(finished=True)
        self.query_one("#evaluation", Static).update(evaluation_table(message.result))
        how = PROTOCOL_WORDS.get(message.result["protocol"], message.result["protocol"])
        self.status(f"evaluated {message.result['n_test']} test windows, {how}")
