"""Step 6 of teach mode, Test: the pose the trained learner gives each taught scene."""

from __future__ import annotations

from typing import Any

from textual.app import ComposeResult
from textual.widgets import DataTable, Label

from servant_core.event_text import angle_text
from servant_tui.screens.teach.step import TeachStep


class PredictionStep(TeachStep):
    """What the arm would do in each taught scene, once the learner is trained."""

    def compose(self) -> ComposeResult:
        yield Label("What the arm would do in each taught scene:")
        yield DataTable(id="predictions")

    def on_mount(self) -> None:
        self.query_one("#predictions", DataTable).add_columns("scene", *self.wizard.joints())

    def show(self, learner: Any) -> None:
        """Each scene `learner` was taught, with the pose it gives that scene for sure."""
        from servant_core.actions.records import label_scores

        table = self.query_one("#predictions", DataTable)
        table.clear()
        for scene in learner.taught_scenes_:
            pose = learner.pose(label_scores(scene, learner.scenes_))
            angles = (angle_text(pose.get(j, float("nan"))) for j in self.wizard.joints())
            table.add_row(scene, *angles, key=scene)
