"""Teach mode's screen: the steps listed on the left, the one chosen shown beside them, and what
the steps share (the scene taught, the arm's joints, the trained learner)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.widget import Widget
from textual.widgets import ContentSwitcher, Footer, Header, Input, OptionList

from servant_core.errors import ServantError
from servant_core.events import SpectrumFrame
from servant_core.library import SceneLibrary
from servant_tui.screens.live import ShowsEvents
from servant_tui.screens.secondary import HELP_AND_QUIT, ServantScreen
from servant_tui.screens.teach.pictures import PicturesStep
from servant_tui.screens.teach.pose import PoseStep
from servant_tui.screens.teach.prediction import PredictionStep
from servant_tui.screens.teach.scene import SceneStep
from servant_tui.screens.teach.sound import SoundStep
from servant_tui.screens.teach.step import TeachStep
from servant_tui.screens.teach.train import TrainStep
from servant_tui.widgets.spectrum import Spectrum

STEPS = (
    ("scene", "1 Scene"),
    ("sound", "2 Sound"),
    ("pictures", "3 Pictures"),
    ("pose", "4 Pose"),
    ("train", "5 Train"),
    ("test", "6 Test"),
)


class TeachScreen(ServantScreen, ShowsEvents):
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
        self.learner: Any = None
        self.spectrum = Spectrum(id="teach-spectrum")

    @property
    def root(self) -> Path:
        return self.app.library_root

    @property
    def windows(self) -> int:
        """The windows of sound recorded for the scene taught."""
        return self.query_one(SoundStep).windows

    @property
    def pictures(self) -> int:
        """The pictures taken of the scene taught."""
        return self.query_one(PicturesStep).pictures

    @property
    def errors(self) -> list[float]:
        """The last training's mean error so far, in degrees."""
        return self.query_one(TrainStep).errors

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
        yield Header()
        with Horizontal(id="teach"):
            yield OptionList(*(label for _, label in STEPS), id="steps")
            with ContentSwitcher(initial="scene", id="step"):
                yield SceneStep(self.known_scenes(), id="scene")
                yield SoundStep(self.spectrum, id="sound")
                yield PicturesStep(id="pictures")
                yield PoseStep(id="pose")
                yield TrainStep(id="train")
                yield PredictionStep(id="test")
        yield Footer()

    def on_mount(self) -> None:
        self.query_one("#steps", OptionList).highlighted = 0
        # Now, not after a refresh: a name typed at once must not go to the steps list
        self.set_focus(self._first_control(self.query_one("#scene")))

    def _first_control(self, step: Widget) -> Widget | None:
        """Where a step's first answer is typed: for the scene (README step 2: "press t, name
        it"), the new scene's name, or the known scenes when there are some; else the step's
        first control in the order it was composed (what the user reads first)."""
        if step.id == "scene":
            return self.query_one("#known" if self.known_scenes() else "#new-scene")
        return next((w for w in step.query("*") if w.focusable), None)

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

    # -- what the steps share ---------------------------------------------------------------------

    def need_scene(self) -> str:
        """The scene taught; ServantError, and step 1 shown, when none is chosen yet."""
        if self.scene is None:
            self.go("scene")
            raise ServantError("teach: pick or name a scene first (step 1)")
        return self.scene

    def use_scene(self) -> None:
        """Teach the scene named or picked in step 1, as its button does."""
        self.query_one(SceneStep).use_scene()

    def teach_another(self) -> None:
        """Every step forgets the scene taught, and step 1 asks for the next one's name."""
        self.scene = None
        for step in self.query(TeachStep):
            step.start_again()
        self.go("scene")
        # Another scene is a new one: its name is typed next (the known scenes came first)
        self.set_focus(self.query_one("#new-scene", Input))

    def show_predictions(self) -> None:
        self.query_one(PredictionStep).show(self.learner)

    def action_remove_sample(self) -> None:
        self.query_one(PoseStep).remove_sample()
