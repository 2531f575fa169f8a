"""Teach mode, step by step: scene, sound, pictures, pose, (repeat), train, test.

Recordings and pictures go straight into the scene library (nothing is lost if the session ends);
each pose becomes a teach record. Training shows the action learner's error falling as it goes.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from datetime import datetime
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from rich.markup import escape
from rich.text import Text
from textual import events, on, work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Horizontal, Vertical
from textual.widget import Widget
from textual.widgets import (
    Button,
    ContentSwitcher,
    DataTable,
    Footer,
    Header,
    Input,
    Label,
    OptionList,
    ProgressBar,
    Select,
    Sparkline,
    Static,
)
from textual.worker import get_current_worker

from servant_core.audio import DEFAULT_WINDOW_SECONDS, write_wav
from servant_core.capture.sample_files import write_sample_csv
from servant_core.engine.learning import retrained_text
from servant_core.errors import ServantError
from servant_core.event_text import angle_text, pose_text
from servant_core.events import SpectrumFrame
from servant_core.features.palette import dominant_colours
from servant_core.library import TEACH_WINDOWS, SceneLibrary
from servant_core.place_names import place_name
from servant_core.senses import SENSES
from servant_core.storage import atomic_write_bytes
from servant_tui.messages import (
    PictureTaken,
    RecordingDone,
    RecordingStopped,
    RetrainDone,
    TrainingDone,
    TrainingProgress,
)
from servant_tui.screens.secondary import HELP_AND_QUIT, ReportsWorkerErrors, with_progress
from servant_tui.widgets.colours import share_strip
from servant_tui.widgets.progress import OnProgress, WorkProgress
from servant_tui.widgets.spectrum import Spectrum
from servant_tui.widgets.text import error_text

STEPS = (
    ("scene", "1 Scene"),
    ("sound", "2 Sound"),
    ("pictures", "3 Pictures"),
    ("pose", "4 Pose"),
    ("train", "5 Train"),
    ("test", "6 Test"),
)


def stamp() -> str:
    return datetime.now().strftime("teach-%Y%m%d-%H%M%S-%f")


# A sample sense records the same seconds as the sound; one whose readings stopped says so this
# long after the sound has been recorded.
SAMPLE_GRACE_SECONDS = 2.0


# Where each step's worker says how it went.
STATUS_OF_WORK = {
    "record": "#sound-status",
    "picture": "#picture-status",
    "train": "#train-status",
    "retrain": "#train-status",
}


# "shoulder 40°, elbow 100°, gripper 60°" and room for a fourth joint
POSE_COLUMN_WIDTH = 48


class KnownScenes(Select[str]):
    """The known scenes' list, where teach mode opens once a scene is known. A name typed at it
    goes into the new name's field, and the Enter after it names the scene: a returning wearer
    typing the new place's name (the README: "press t, name it") saw nothing happen, the list
    took the letters and Enter opened it. Keys come from the terminal in a burst, all given to
    the list before the first moves the focus, so every letter the list gets is passed on."""

    def passes_on(self, character: str | None) -> bool:
        """Whether a key typed here goes to the name's field: a letter, not Enter, space or an
        arrow (they still open the list), and not while the list is open."""
        typed = character or ""
        return not self.expanded and typed.isprintable() and bool(typed.strip())

    def check_consume_key(self, key: str, character: str | None = None) -> bool:
        # the letters are the name's, like a field's: the footer offers no key they type
        return self.passes_on(character)

    def on_key(self, event: events.Key) -> None:
        if not self.passes_on(event.character):
            return
        field = self.screen.query_one("#new-scene", Input)
        self.screen.set_focus(field)
        field.insert_text_at_cursor(event.character or "")
        event.stop()


def every_press(button: Button) -> Button:
    """`button`, each press of which counts. Textual ignores a press within its press animation
    (0.2 s, ended by a timer): two quick Enters on *Take picture* took one picture, and on a
    loaded machine, where the timer ran late, a press after the first picture was on the screen
    was lost."""
    button.active_effect_duration = 0
    return button


class TeachScreen(ReportsWorkerErrors):
    BINDINGS = [
        Binding("escape", "app.pop_screen", "Back"),
        # Priority: the app runs the step change before it forwards the next key of a burst.
        Binding("ctrl+n", "step(1)", "Next", priority=True),
        Binding("ctrl+b", "step(-1)", "Previous", priority=True),
        Binding("delete", "remove_sample", "Remove sample", show=False),
        *HELP_AND_QUIT,
    ]

    def __init__(self) -> None:
        super().__init__()
        self.scene: str | None = None
        self.windows = 0
        self.pictures = 0
        self.errors: list[float] = []
        self.learner: Any = None
        self.spectrum = Spectrum(id="teach-spectrum")
        self._recording_started: float | None = None
        self._samples: dict[str, Any] = {}  # the samples table's rows: key -> teach record
        self._one_picture_at_a_time = threading.Lock()

    @property
    def root(self) -> Path:
        return self.app.library_root

    def settings(self) -> Any:
        """The user's settings (loaded once for the app), or None if they cannot be read."""
        from servant_core.settings import load_settings

        if self.app.settings is None:
            try:
                self.app.settings = load_settings()
            except ServantError as error:
                self.app.report_error(error)
        return self.app.settings

    def joints(self) -> list[str]:
        """The connected arm's joints, else the configured ones."""
        if self.app.arm_state is not None and self.app.arm_state.angles:
            return list(self.app.arm_state.angles)
        settings = self.settings()
        return [] if settings is None else [joint.name for joint in settings.joints]

    def known_scenes(self) -> list[str]:
        """The library's scenes and those the engine's recognisers know (the demo's, say)."""
        scenes = set(SceneLibrary.scan(self.root).scenes) if self.root.is_dir() else set()
        return sorted(scenes | self.app.known_scenes)

    def compose(self) -> ComposeResult:
        scenes = self.known_scenes()
        yield Header()
        with Horizontal(id="teach"):
            yield OptionList(*(label for _, label in STEPS), id="steps")
            with ContentSwitcher(initial="scene", id="step"):
                with Vertical(id="scene"):
                    yield Label("Pick the scene you are in, or name a new one.")
                    yield KnownScenes([(s, s) for s in scenes], prompt="known scenes", id="known")
                    yield Input(
                        placeholder="new scene name, e.g. CoffeeScene",
                        id="new-scene",
                        select_on_focus=False,  # a letter the known scenes passed on stays
                    )
                    yield Button("Use this scene", id="use-scene", variant="primary")
                with Vertical(id="sound"):
                    yield Label(
                        f"Record {DEFAULT_WINDOW_SECONDS:g} s of the place's sound"
                        f"{self._with_senses()}, {TEACH_WINDOWS} times: the place is recognised "
                        f"far more often from {TEACH_WINDOWS * DEFAULT_WINDOW_SECONDS:g} s than "
                        "from a few."
                    )
                    yield every_press(
                        Button(
                            f"Record {DEFAULT_WINDOW_SECONDS:g} s", id="record", variant="primary"
                        )
                    )
                    yield ProgressBar(
                        total=DEFAULT_WINDOW_SECONDS, show_eta=False, id="record-progress"
                    )
                    yield self.spectrum
                    yield Static(id="sound-status")
                with Vertical(id="pictures"):
                    yield Label(
                        "Take pictures of the place (the camera's dominant colours are learnt)."
                    )
                    yield every_press(Button("Take picture", id="take-picture", variant="primary"))
                    yield Static(id="picture-status")
                with Vertical(id="pose"):
                    yield Label("The arm's pose for this scene: type the angles, or guide the arm.")
                    with Grid(id="pose-form"):
                        for joint in self.joints():
                            yield Label(joint)
                            yield Input(id=f"joint-{joint}", type="number", placeholder="degrees")
                    with Horizontal(classes="buttons"):
                        yield Button("Use the arm's pose", id="guided")
                        yield every_press(Button("Add sample", id="add-sample", variant="primary"))
                        yield Button("Teach another scene", id="again")
                    yield DataTable(id="samples", cursor_type="row")
                    yield Label("A wrong sample? Select it and press delete.", classes="hint")
                with Vertical(id="train"):
                    yield Label(
                        "Learn scene → pose from every teach record; retrain the recognisers."
                    )
                    with Horizontal(classes="buttons"):
                        yield Button("Train", id="train-learner", variant="primary")
                        yield Button("Retrain recognisers", id="retrain")
                    # empty until Train is pressed: a bar of unknown length would animate
                    # as if a job were running
                    yield ProgressBar(total=1, show_eta=False, id="train-progress")
                    yield WorkProgress(id="retrain-progress")
                    yield Sparkline([], id="error-curve")
                    yield Static(id="train-status")
                with Vertical(id="test"):
                    yield Label("What the arm would do in each taught scene:")
                    yield DataTable(id="predictions")
        yield Footer()

    def on_mount(self) -> None:
        self.query_one("#error-curve").border_title = "training error (degrees)"
        samples = self.query_one("#samples", DataTable)
        samples.add_column("scene")
        # a width of its own: left to fit its content, the pose of the first sample added (from
        # a worker) sometimes kept the header's four cells ("shou"; issue 39 item 15)
        samples.add_column("pose", width=POSE_COLUMN_WIDTH)
        samples.add_column("source")
        self._list_samples()
        self.query_one("#predictions", DataTable).add_columns("scene", *self.joints())
        self.query_one("#steps", OptionList).highlighted = 0
        self.set_interval(0.1, self._tick_recording, pause=False)
        # Now, not after a refresh: a name typed at once must not go to the steps list
        self.set_focus(self._first_control(self.query_one("#scene")))

    def _first_control(self, step: Widget) -> Widget | None:
        """Where a step's first answer is typed: for the scene (README step 2: "press t, name
        it"), the new scene's name, or the known scenes when there are some; else the step's
        first control in the order it was composed (what the user reads first)."""
        if step.id == "scene":
            return self.query_one("#known" if self.known_scenes() else "#new-scene")
        return next((w for w in step.query("*") if w.focusable), None)

    def sample_senses(self) -> list[str]:
        """The engine's sample senses (motion, ambient): recorded with the sound."""
        return list(self.app.engine.sample_senses)

    def _with_senses(self) -> str:
        senses = self.sample_senses()
        return f", with its {' and '.join(senses)}" if senses else ""

    def show_event(self, event: object) -> None:
        if isinstance(event, SpectrumFrame):
            self.spectrum.show_frame(event)

    # -- navigation -------------------------------------------------------------------------------

    @on(OptionList.OptionHighlighted, "#steps")
    def _step_chosen(self, event: OptionList.OptionHighlighted) -> None:
        self._show(event.option_index)

    def _show(self, index: int) -> None:
        """Step `index` shown, and the focus in it at once. Keys arrive from a terminal in a
        burst: those typed right after a step change (Ctrl-N, then an angle) went to the hidden
        step's control while the focus waited (`Widget.focus` is deferred, and the focus chain
        is in layout order only after the next refresh). The focus stays on the steps list or
        on a control of the step shown; else it goes to the step's first control as composed,
        so Enter acts on what the user sees."""
        switcher = self.query_one(ContentSwitcher)
        switcher.current = STEPS[index][0]
        step = switcher.visible_content
        focused = self.focused
        if step is None or (focused is not None and focused.id == "steps"):
            return
        if focused is not None and step in focused.ancestors:
            return
        first = self._first_control(step)
        if first is not None:
            self.set_focus(first)

    def go(self, step: str) -> None:
        index = [s for s, _ in STEPS].index(step)
        self.query_one("#steps", OptionList).highlighted = index
        self._show(index)

    def action_step(self, delta: int) -> None:
        steps = self.query_one("#steps", OptionList)
        index = min(max((steps.highlighted or 0) + delta, 0), len(STEPS) - 1)
        steps.highlighted = index
        self._show(index)

    def _need_scene(self) -> str:
        if self.scene is None:
            self.go("scene")
            raise ServantError("teach: pick or name a scene first (step 1)")
        return self.scene

    # -- 1 scene ----------------------------------------------------------------------------------

    @on(Input.Submitted, "#new-scene")
    @on(Button.Pressed, "#use-scene")
    def use_scene(self) -> None:
        typed = self.query_one("#new-scene", Input).value.strip()
        known = self.query_one("#known", Select).value
        scene = typed or (known if isinstance(known, str) else None)
        if not scene:
            self.notify("Pick a known scene or type a new name.", severity="warning")
            return
        try:
            scene = place_name(scene, self.root, self.known_scenes())
        except ServantError as error:
            self.app.report_error(error)
            return
        self.scene = scene
        self.sub_title = f"teaching {scene}"
        self.app.log_line(None, f"teaching scene {escape(scene)}")
        self.go("sound")

    # -- 2 sound ----------------------------------------------------------------------------------

    @on(Button.Pressed, "#record")
    def start_recording(self) -> None:
        scene = self._try(self._need_scene)
        if scene is None:
            return
        self.query_one("#record", Button).disabled = True
        self._recording_started = time.monotonic()
        self.record(scene)

    def _tick_recording(self) -> None:
        if self._recording_started is not None:
            elapsed = time.monotonic() - self._recording_started
            self.query_one("#record-progress", ProgressBar).update(
                progress=min(elapsed, DEFAULT_WINDOW_SECONDS)
            )

    @work(thread=True, exclusive=True, group="record", exit_on_error=False)
    def record(self, scene: str) -> None:
        """The next seconds of sound into `<scene>/teach-….wav`, and the same seconds of each
        sample sense beside it (`….imu.csv`, `….ambient.csv`). The sample senses record in
        parallel with the sound, each on a thread of its own, since each records the seconds
        from when it is asked. A sensor that fails loses only its own log: the sound is kept,
        and the failure is one line in the log and a notification.

        Teach mode closing (Escape, or the app quitting) stops the recording at once: Textual
        sets this worker's cancelled event as the screen goes, and the engine's recordings
        watch it (`q` waited out the recording's 12 s timeout on a blank terminal, the engine
        stopped). Nothing of a stopped recording is written, and the screen, gone, is not
        touched again: the app says so in the log."""
        stop = get_current_worker().cancelled_event
        app = self.app  # a screen that has gone no longer knows its app
        engine = app.engine
        senses = self.sample_senses()
        folder, name = self.root / scene, stamp()
        try:
            with ThreadPoolExecutor(max(len(senses), 1), thread_name_prefix="teach") as pool:
                feeling = {
                    sense: pool.submit(
                        engine.record_samples,
                        sense,
                        DEFAULT_WINDOW_SECONDS,
                        DEFAULT_WINDOW_SECONDS + SAMPLE_GRACE_SECONDS,
                        stop,
                    )
                    for sense in senses
                }
                sound = engine.record_window(DEFAULT_WINDOW_SECONDS, cancel=stop)
                if stop.is_set():  # in full as teach mode closed: it is not kept either
                    raise ServantError("teach: closed while recording")
                audio = np.asarray(sound, dtype=np.float32)
                rate = engine.audio_rate
                path = write_wav(folder / f"{name}.wav", audio, rate)
                logs = [self._write_log(folder, name, s, f, path, stop) for s, f in feeling.items()]
        except ServantError:
            if stop.is_set():
                app.post_message(RecordingStopped(scene))
                return
            raise
        finally:
            if not stop.is_set():
                app.call_from_thread(self._recording_over)
        written = tuple(log for log in logs if log is not None)
        self.post_message(RecordingDone(path, len(audio) / rate, written))

    def _write_log(
        self,
        folder: Path,
        name: str,
        sense: str,
        recording: Future[Any],
        sound: Path,
        stop: threading.Event,
    ) -> Path | None:
        """Write a sample sense's recording beside the sound; None (said in one line) if the
        sensor failed, or (not said: the screen is going) if teach mode closed meanwhile."""
        try:
            rows, rate = recording.result()
        except ServantError as error:
            if not stop.is_set():
                self.app.call_from_thread(
                    self.app.report_error,
                    ServantError(
                        f"{sense}: not recorded ({error}); the sound {sound.name} was kept"
                    ),
                )
            return None
        kind = SENSES[sense]
        return write_sample_csv(folder / f"{name}{kind.suffixes[0]}", rows, rate, str(kind.stream))

    def _recording_over(self) -> None:
        """The button back, and the focus on it while the sound step shows: disabling it took
        the focus away, and Enter (record another) then did nothing."""
        self._recording_started = None
        record = self.query_one("#record", Button)
        record.disabled = False
        if self.query_one("#step", ContentSwitcher).current == "sound":
            record.focus()

    @on(RecordingDone)
    def recorded(self, message: RecordingDone) -> None:
        self.windows += 1
        self.query_one("#record-progress", ProgressBar).update(progress=DEFAULT_WINDOW_SECONDS)
        logs = ", ".join(p.name for p in message.samples)
        left = TEACH_WINDOWS - self.windows
        more = f", {left} more to go" if left > 0 else ""
        self.query_one("#sound-status", Static).update(
            f"{self.windows} window(s) recorded{more}; last: {message.path.name} "
            f"({message.seconds:.1f} s)" + (f" with {logs}" if logs else "")
        )
        for path in (message.path, *message.samples):
            self.app.log_line(None, f"recorded {path}")

    # -- 3 pictures -------------------------------------------------------------------------------

    @on(Button.Pressed, "#take-picture")
    def start_picture(self) -> None:
        scene = self._try(self._need_scene)
        if scene is not None:
            self.take_picture(scene)

    # not exclusive: each press is a picture (an exclusive worker cancelled the one before it,
    # so three quick Enters took one); taken one at a time, each under its own time stamp
    @work(thread=True, group="picture", exit_on_error=False)
    def take_picture(self, scene: str) -> None:
        with self._one_picture_at_a_time:
            frame = self.app.engine.take_picture()
            ok, png = cv2.imencode(".png", frame)
            if not ok:
                raise ServantError("camera: the picture could not be encoded; try again")
            path = atomic_write_bytes(self.root / scene / f"{stamp()}.png", png.tobytes())
        colours, shares = dominant_colours(frame)
        self.post_message(PictureTaken(path, colours, shares))

    @on(PictureTaken)
    def pictured(self, message: PictureTaken) -> None:
        self.pictures += 1
        text = Text(f"{self.pictures} picture(s) taken; last: {message.path.name}\n")
        text.append_text(share_strip(np.asarray(message.colours), np.asarray(message.shares), 40))
        self.query_one("#picture-status", Static).update(text)
        self.app.log_line(None, f"took {message.path}")

    # -- 4 pose -----------------------------------------------------------------------------------

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
        settings = self.settings()
        for joint in self.joints():
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

        try:
            scene = self._need_scene()
            pose = self.typed_pose()
            scenes = SceneLibrary.scan(self.root).scenes if self.root.is_dir() else [scene]
            source = getattr(self, "_source", "typed")
            record = TeachRecord(scene, label_scores(scene, scenes), pose, time.time(), source)
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
        order = {joint: i for i, joint in enumerate(self.joints())}
        pose = dict(sorted(record.pose.items(), key=lambda item: order.get(item[0], len(order))))
        self.query_one("#samples", DataTable).add_row(
            record.scene, pose_text(pose), record.source, key=key
        )

    def _list_samples(self) -> None:
        """Every teach record in the file, this session's and earlier ones."""
        from servant_core.actions.records import load_records

        self.query_one("#samples", DataTable).clear()
        self._samples = {}
        for record in self._try(load_records) or []:
            self._show_sample(record)

    def action_remove_sample(self) -> None:
        """Remove the teach record selected in the samples table (a mistyped angle would
        otherwise be averaged into the scene's pose for good)."""
        from servant_core.actions.records import load_records, save_records

        table = self.query_one("#samples", DataTable)
        if self.focused is not table or table.row_count == 0:
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

    @on(Button.Pressed, "#again")
    def teach_another(self) -> None:
        self.scene = None
        self.windows = self.pictures = 0
        self._source = "typed"
        for field in self.query("#pose-form Input").results(Input):
            field.value = ""  # the next place's pose is its own
        self.query_one("#new-scene", Input).value = ""
        self.query_one("#known", Select).set_options((s, s) for s in self.known_scenes())
        self.go("scene")
        # Another scene is a new one: its name is typed next (the known scenes came first)
        self.set_focus(self.query_one("#new-scene", Input))

    # -- 5 train ----------------------------------------------------------------------------------

    @on(Button.Pressed, "#train-learner")
    def start_training(self) -> None:
        self.errors = []
        self.query_one("#train-learner", Button).disabled = True
        self.train(self.settings())

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
            self.app.call_from_thread(
                setattr, self.query_one("#train-learner", Button), "disabled", False
            )
        self.post_message(TrainingDone(learner))

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
        self.learner = message.learner
        final = self.errors[-1] if self.errors else float("nan")
        summary = f"trained on {message.learner.n_records_} teach records; error {final:.2f}°"
        # README step 3 goes on with Retrain in this step: the focus goes there (jumping to the
        # Test step left Retrain a step back, out of Enter's reach); Test shows the poses
        self.query_one("#train-status", Static).update(
            f"{summary}. Next: Retrain recognisers; the poses are in the Test step."
        )
        self.app.log_line(None, summary)
        self.show_predictions()
        if self.query_one(ContentSwitcher).current == "train":
            self.query_one("#retrain", Button).focus()

    @on(Button.Pressed, "#retrain")
    def start_retrain(self) -> None:
        self.query_one("#train-status", Static).update("retraining the recognisers…")
        self.retrain(self.query_one("#retrain-progress", WorkProgress).begin())

    @work(thread=True, exclusive=True, group="retrain", exit_on_error=False)
    def retrain(self, on_progress: OnProgress) -> None:
        library = SceneLibrary.scan(self.root)
        senses = with_progress(self.app.engine.retrain, library, on_progress)
        self.post_message(RetrainDone(retrained_text(senses, library)))

    @on(RetrainDone)
    def retrained(self, message: RetrainDone) -> None:
        self.query_one("#retrain-progress", WorkProgress).end(finished=True)
        self.query_one("#train-status", Static).update(message.summary)
        self.app.log_line(None, message.summary)

    # -- 6 test -----------------------------------------------------------------------------------

    def show_predictions(self) -> None:
        from servant_core.actions.records import label_scores

        table = self.query_one("#predictions", DataTable)
        table.clear()
        learner = self.learner
        for scene in learner.taught_scenes_:
            pose = learner.pose(label_scores(scene, learner.scenes_))
            table.add_row(
                scene, *(angle_text(pose.get(j, float("nan"))) for j in self.joints()), key=scene
            )

    def work_failed(self, group: str, error: BaseException) -> None:
        if group == "retrain":
            self.query_one("#retrain-progress", WorkProgress).end(finished=False)
        status = STATUS_OF_WORK.get(group)
        if status is not None:
            self.query_one(status, Static).update(
                Text.assemble((f"{group} failed: ", "bold red"), error_text(error))
            )

    def _try(self, step: Any) -> Any:
        try:
            return step()
        except ServantError as error:
            self.app.report_error(error)
            return None
