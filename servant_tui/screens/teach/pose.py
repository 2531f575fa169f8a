"""Step 4 of teach mode: the arm's pose for the scene, typed or read from the arm, kept as a
teach record; the samples so far, a wrong one removable."""

from __future__ import annotations

import time
from typing import Any

from textual import on, work
from textual.app import ComposeResult
from textual.containers import Grid, Horizontal
from textual.widgets import Button, DataTable, Input, Label

from servant_core.errors import ServantError
from servant_core.event_text import pose_text
from servant_core.library import SceneLibrary
from servant_tui.screens.teach.step import TeachStep, every_press

# "shoulder 40°, elbow 100°, gripper 60°" and room for a fourth joint
POSE_COLUMN_WIDTH = 48


class PoseStep(TeachStep):
    """*Add sample* keeps the pose typed (or read from the arm) as the scene's teach record."""

    def __init__(self, *, id: str) -> None:
        super().__init__(id=id)
        self._source = "typed"  # of the pose in the fields: "recorded" once read from the arm
        self._samples: dict[str, Any] = {}  # the samples table's rows: key -> teach record

    def compose(self) -> ComposeResult:
        yield Label("The arm's pose for this scene: type the angles, or guide the arm.")
        with Grid(id="pose-form"):
            for joint in self.wizard.joints():
                yield Label(joint)
                yield Input(id=f"joint-{joint}", type="number", placeholder="degrees")
        with Horizontal(classes="buttons"):
            yield Button("Use the arm's pose", id="guided")
            yield every_press(Button("Add sample", id="add-sample", variant="primary"))
            yield Button("Teach another scene", id="again")
        yield DataTable(id="samples", cursor_type="row")
        yield Label("A wrong sample? Select it and press delete.", classes="hint")

    def on_mount(self) -> None:
        samples = self.query_one("#samples", DataTable)
        samples.add_column("scene")
        # a width of its own: left to fit its content, the pose of the first sample added (from
        # a worker) sometimes kept the header's four cells ("shou"; issue 39 item 15)
        samples.add_column("pose", width=POSE_COLUMN_WIDTH)
        samples.add_column("source")
        self._list_samples()

    def start_again(self) -> None:
        self._source = "typed"
        for field in self.query("#pose-form Input").results(Input):
            field.value = ""  # the next place's pose is its own

    @on(Button.Pressed, "#again")
    def teach_another(self) -> None:
        self.wizard.teach_another()

    @on(Button.Pressed, "#guided")
    def use_arm_pose(self) -> None:
        self.read_arm_pose()

    @work(thread=True, exclusive=True, group="arm-pose", exit_on_error=False)
    def read_arm_pose(self) -> None:
        """Ask the controller where the arm is (a serial exchange, off the UI thread): armed or
        not, since the wearer guides the arm by hand disarmed."""
        self.app.call_from_thread(self._fill_pose, self.app.engine.read_arm_pose())

    def _fill_pose(self, pose: dict[str, float]) -> None:
        # whole degrees: the controller's pulse steps read back as 19.98° for 20°
        whole = {joint: float(round(angle)) for joint, angle in pose.items()}
        for joint, angle in whole.items():
            for field in self.query(f"#joint-{joint}").results(Input):
                field.value = f"{angle:g}"
        self._source = "recorded"
        self.app.log_line(None, f"read the arm's pose: {pose_text(whole)}")

    def typed_pose(self) -> dict[str, float]:
        pose = {}
        settings = self.wizard.settings()
        for joint in self.wizard.joints():
            text = self.query_one(f"#joint-{joint}", Input).value.strip()
            try:
                angle = float(text)
            except ValueError:
                raise ServantError(
                    f"pose: {joint} needs an angle in degrees (got {text!r})"
                ) from None
            if settings is not None and joint in {j.name for j in settings.joints}:
                limits = settings.joint(joint)
                if not limits.min_angle <= angle <= limits.max_angle:
                    raise ServantError(
                        f"pose: {joint} {angle:g}° is outside its limits "
                        f"{limits.min_angle:g}..{limits.max_angle:g}°; "
                        "change the angle or the limits in Settings"
                    )
            pose[joint] = angle
        return pose

    @on(Button.Pressed, "#add-sample")
    def add_sample(self) -> None:
        from servant_core.actions.records import TeachRecord, append_record, label_scores

        root = self.wizard.root
        try:
            scene = self.wizard.need_scene()
            pose = self.typed_pose()
            scenes = SceneLibrary.scan(root).scenes if root.is_dir() else [scene]
            record = TeachRecord(
                scene, label_scores(scene, scenes), pose, time.time(), self._source
            )
            append_record(record)
        except ServantError as error:
            self.app.report_error(error)
            return
        self._source = "typed"
        self._show_sample(record)
        self.app.log_line(None, f"taught {scene}: {pose_text(pose)}")

    def _show_sample(self, record: Any) -> None:
        """A sample's row, its joints in the arm's order (the file keeps them sorted by name:
        an earlier session's samples read "elbow, gripper, shoulder" beside this one's)."""
        key = str(len(self._samples))
        self._samples[key] = record
        order = {joint: i for i, joint in enumerate(self.wizard.joints())}
        pose = dict(sorted(record.pose.items(), key=lambda item: order.get(item[0], len(order))))
        self.query_one("#samples", DataTable).add_row(
            record.scene, pose_text(pose), record.source, key=key
        )

    def _list_samples(self) -> None:
        """Every teach record in the file, this session's and earlier ones."""
        from servant_core.actions.records import load_records

        self.query_one("#samples", DataTable).clear()
        self._samples = {}
        for record in self.attempt(load_records) or []:
            self._show_sample(record)

    def remove_sample(self) -> None:
        """Remove the teach record selected in the samples table (a mistyped angle would
        otherwise be averaged into the scene's pose for good)."""
        from servant_core.actions.records import load_records, save_records

        table = self.query_one("#samples", DataTable)
        if self.screen.focused is not table or table.row_count == 0:
            self.notify("Select a sample in the list of samples, then press delete.")
            return
        key = table.coordinate_to_cell_key(table.cursor_coordinate).row_key.value
        chosen = self._samples.get(str(key))
        try:
            records = load_records()
            kept = [r for r in records if r != chosen]
            if chosen is None or len(kept) == len(records):
                raise ServantError("teach: that sample is no longer in the teach records")
            save_records(kept)
        except ServantError as error:
            self.app.report_error(error)
            return
        self._list_samples()
        self.app.log_line(None, f"removed a sample of {chosen.scene}: {pose_text(chosen.pose)}")
