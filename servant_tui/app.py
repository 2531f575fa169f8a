"""The Servant terminal application: the engine is handed in, the screens show what it emits."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from rich.markup import escape
from textual import on, work
from textual.app import App, SystemCommand
from textual.binding import Binding
from textual.screen import Screen
from textual.worker import Worker, WorkerState

from servant_core.event_text import left_text
from servant_core.events import (
    AcousticPrediction,
    ArmState,
    DeviceStatus,
    ErrorEvent,
    Notice,
    SensorFrame,
    SpectrumFrame,
    UnknownScene,
    VisualPrediction,
)
from servant_core.fusion.sequential import scene_line
from servant_core.log_news import LogNews
from servant_core.storage import data_dir
from servant_tui.heap import release_free_heap
from servant_tui.log_text import log_text
from servant_tui.messages import (
    EngineEvent,
    RecordingStopped,
    SensorUpdate,
    SpectrumUpdate,
    TrainingDone,
)
from servant_tui.place_question import PROMPT_EVERY_S as PROMPT_EVERY_S  # bench/wearer_day
from servant_tui.place_question import PlaceQuestion
from servant_tui.screens.dialogs import HelpScreen
from servant_tui.screens.live import LiveScreen, ShowsEvents, device_message
from servant_tui.widgets.text import clock, error_text

if TYPE_CHECKING:
    from threading import Event

    import numpy as np

    from servant_core.library import SceneLibrary


@runtime_checkable
class EngineLike(Protocol):
    """What the application asks of the engine (`servant_core.engine.Engine` or a test replay)."""

    library_root: Path | None  # where teach mode and the Library screen keep the scenes
    model_path: Path | None  # where a retrain or a label saves the model (None: not saved)
    user_settings: Any  # the settings it runs on (`servant_core.settings.Settings`), or None
    # its `retrain` takes `on_progress(done, total)` (else the app counts the files it walks)
    retrain_reports_progress: bool
    # its sound and picture recognisers (their `scenes_` and `method`), None before one is fitted
    acoustic: Any
    visual: Any

    @property
    def audio_rate(self) -> int: ...
    @property
    def sample_senses(self) -> list[str]: ...

    def subscribe(self, callback: Callable[[Any], None]) -> Any: ...
    def start(self) -> None: ...
    def stop(self) -> None: ...
    def arm(self) -> None: ...
    def disarm(self) -> None: ...
    def label_unknown(self, window_id: str, scene: str) -> Any: ...
    def apply_settings(self, settings: Any) -> None: ...
    def set_action_learner(self, pose_for: Any) -> None: ...
    def read_arm_pose(self) -> dict[str, float]: ...
    # both end at once, raising ServantError, when `cancel` is set (teach mode closing)
    def record_window(
        self, seconds: float, timeout: float | None = None, cancel: Event | None = None
    ) -> np.ndarray: ...
    def record_samples(
        self, sense: str, seconds: float, timeout: float | None, cancel: Event | None = None
    ) -> tuple[np.ndarray, int]: ...
    def take_picture(self) -> np.ndarray: ...
    def retrain(self, library: SceneLibrary) -> Any: ...


def default_library_root() -> Path:
    return data_dir() / "library"


# How often the C heaps' free pages go back to the system. Under an open dialog Textual redraws
# the whole screen beneath it for every engine event; each redraw's short-lived strips and
# segments leave free pages in glibc's heaps (its per-thread arenas among them) that it does not
# return by itself (issue 13's soak, a prompt left open: +4.4 MB/h untrimmed, +0.8 trimmed).
HEAP_TRIM_EVERY_S = 60.0


class ServantApp(App[None]):
    TITLE = "Servant"
    CSS_PATH = "app.tcss"
    # app.tcss lays the screens out tighter below 100 columns (80x24 must be usable)
    HORIZONTAL_BREAKPOINTS = [(0, "-narrow"), (100, "-wide")]
    VERTICAL_BREAKPOINTS = [(0, "-short"), (30, "-tall")]
    BINDINGS = [
        Binding("a", "toggle_arm", "Arm/Disarm"),
        Binding("t", "teach", "Teach"),
        Binding("l", "library", "Library"),
        Binding("s", "settings", "Settings"),
        Binding("question_mark,f1", "help", "Help", key_display="?"),
        Binding("q", "quit", "Quit"),
        # Priority: the app moves the focus before it forwards the next key of a burst (the
        # angles "40", Tab, "100" typed quickly all went into the first field: a Tab bubbling up
        # from the field ran only after the digits behind it had been given to that field)
        Binding("tab", "focus_next", show=False, priority=True),
        Binding("shift+tab", "focus_previous", show=False, priority=True),
    ]

    def __init__(
        self,
        engine: EngineLike,
        *,
        mode: str = "live",
        library_root: Path | None = None,
        settings: Any = None,
    ) -> None:
        super().__init__()
        self.engine = engine
        self.sub_title = "demo scenes" if mode == "demo" else "live devices"
        self.library_root = library_root or engine.library_root or default_library_root()
        # the settings the engine runs on (with `servant run`'s overrides), else loaded from the
        # file by the first screen that needs them
        self._settings = settings or engine.user_settings
        self.arm_state: ArmState | None = None
        self.seen_scenes: set[str] = set()
        self.live = LiveScreen(sample_senses=engine.sample_senses)
        self.question = PlaceQuestion(self)  # "What is this place?"
        self._noticed: set[str] = set()
        self.news = LogNews()  # which events the log says, as `servant run --headless` does
        engine.subscribe(self._from_engine)

    @property
    def settings(self) -> Any:
        """The user's settings (`servant_core.settings.Settings`), loaded by the first screen
        that needs them. Setting them (the Settings screen, after saving) hands them to the
        engine: fusion windows, confidence threshold and the arm's port reach the live engine."""
        return self._settings

    @settings.setter
    def settings(self, value: Any) -> None:
        self._settings = value
        if value is not None:
            self.apply_settings(value)

    @work(thread=True, exclusive=True, group="apply-settings", exit_on_error=False)
    def apply_settings(self, settings: Any) -> None:
        self.engine.apply_settings(settings)

    @property
    def known_scenes(self) -> set[str]:
        """The scenes the engine's recognisers know, and any it was heard or seen to name."""
        known = set(self.seen_scenes)
        for recogniser in (self.engine.acoustic, self.engine.visual):
            if recogniser is not None:
                known.update(str(s) for s in recogniser.scenes_)
        return known

    @on(TrainingDone)
    def _use_taught_poses(self, message: TrainingDone) -> None:
        """Teach mode trained the action learner: the arm acts on its poses from now on."""
        if message.learner is not None:
            from servant_core.engine import pose_for_taught

            self.engine.set_action_learner(pose_for_taught(message.learner))

    @on(RecordingStopped)
    def _recording_stopped(self, message: RecordingStopped) -> None:
        self.log_line(
            None,
            f"[yellow]teach mode closed while recording {escape(message.scene)}: that "
            "recording was stopped and not kept[/]",
        )

    # -- the engine side -------------------------------------------------------------------------

    def _from_engine(self, event: Any) -> None:
        """Called on engine threads: hand the event to the UI thread as a message, nothing more."""
        if isinstance(event, SpectrumFrame):
            self.post_message(SpectrumUpdate(event))
        elif isinstance(event, SensorFrame):
            self.post_message(SensorUpdate(event))
        else:
            self.post_message(EngineEvent(event))

    def get_default_screen(self) -> Screen[Any]:
        return self.live

    def on_mount(self) -> None:
        self.set_interval(HEAP_TRIM_EVERY_S, release_free_heap, name="heap trim")
        self.start_engine()

    @work(thread=True, exclusive=True, group="engine", exit_on_error=False)
    def start_engine(self) -> None:
        self.engine.start()

    def on_unmount(self) -> None:
        # Joining the engine's threads closes the audio stream, the camera and the serial port.
        self.engine.stop()

    @on(SpectrumUpdate)
    def _spectrum(self, message: SpectrumUpdate) -> None:
        for screen in self._event_screens():
            screen.show_event(message.frame)

    @on(SensorUpdate)
    def _sensor(self, message: SensorUpdate) -> None:
        for screen in self._event_screens():
            screen.show_event(message.frame)

    @on(EngineEvent)
    def _event(self, message: EngineEvent) -> None:
        event = message.event
        if isinstance(event, ArmState):
            changed = self.arm_state is None or (
                (self.arm_state.armed, self.arm_state.connected) != (event.armed, event.connected)
            )
            self.arm_state = event
            if changed:
                self.refresh_bindings()
        elif isinstance(event, (AcousticPrediction, VisualPrediction)) and event.scene:
            self.seen_scenes.add(event.scene)
            if isinstance(event, AcousticPrediction):
                # the next unknown place met behind a screen is logged
                self.question.deferred = False
        news = self.news(event)
        line = self._log_text(event) if news.said else None
        if line:
            self.log_line(event.t, line)
        if news.left is not None:
            why = escape(left_text(news.left, news.silent))
            self.log_line(event.t, f"[yellow]{escape(scene_line(None))} [/]({why})")
        if isinstance(event, ErrorEvent):
            self.notify(event.message, title="Servant", severity="error")
        elif isinstance(event, Notice) and event.message not in self._noticed:
            self._noticed.add(event.message)  # said once as a notification; always in the log
            self.notify(event.message, title="Servant", timeout=10)
        elif isinstance(event, DeviceStatus) and not event.ok:
            self.notify(f"{event.device}: {device_message(event)}", severity="warning")
        elif isinstance(event, UnknownScene):
            self.question.ask(event)
        self.question.withdraw_if_stale(event)
        for screen in self._event_screens():
            screen.show_event(event)

    def _event_screens(self) -> Iterable[ShowsEvents]:
        return [s for s in self.screen_stack if isinstance(s, ShowsEvents)]

    _log_text = staticmethod(log_text)  # the log's line for an event

    def log_line(self, t: float | None, line: str) -> None:
        # the space ends the styled run: a reader trimming runs keeps the words apart
        stamp = f"[dim]{clock(t)} [/]" if t is not None else ""
        self.live.write_log(stamp + line)

    def report_error(self, error: BaseException) -> None:
        """Errors a user can cause go to the log and a notification; the application stays up."""
        text = error_text(error)
        self.log_line(None, f"[bold red]{escape(text)}[/]")
        self.notify(text, title="Servant", severity="error", timeout=8)

    def on_worker_state_changed(self, event: Worker.StateChanged) -> None:
        if event.state == WorkerState.ERROR and event.worker.error is not None:
            self.report_error(event.worker.error)

    # -- open set: the wearer names a place (`place_question.PlaceQuestion` asks) -------------

    @work(thread=True, group="label", exit_on_error=False)
    def label_unknown(self, window_id: str, scene: str) -> None:
        self.engine.label_unknown(window_id, scene)
        saved = self.engine.model_path
        where = f"; model saved to {escape(str(saved))}" if saved else " (kept until you quit)"
        self.call_from_thread(
            self.log_line, None, f"labelled the unknown place as {escape(scene)}{where}"
        )

    # -- actions ----------------------------------------------------------------------------------

    def action_toggle_arm(self) -> None:
        self.toggle_arm(not (self.arm_state is not None and self.arm_state.armed))

    @work(thread=True, exclusive=True, group="arm", exit_on_error=False)
    def toggle_arm(self, armed: bool) -> None:
        if armed:
            self.engine.arm()
        else:
            self.engine.disarm()

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action == "toggle_arm":
            return self.arm_state is not None and self.arm_state.connected
        return True

    def action_help(self) -> None:
        if not isinstance(self.screen, HelpScreen):
            self.push_screen(HelpScreen())

    def action_teach(self) -> None:
        from servant_tui.screens.teach import TeachScreen

        self._open(TeachScreen)

    def action_library(self) -> None:
        from servant_tui.screens.library import LibraryScreen

        self._open(LibraryScreen)

    def action_settings(self) -> None:
        from servant_tui.screens.settings import SettingsScreen

        self._open(SettingsScreen)

    def _open(self, screen_type: type[Screen[Any]]) -> None:
        """Open a screen over the live one, replacing another secondary screen if one is open."""
        if isinstance(self.screen, screen_type):
            return
        while len(self.screen_stack) > 1:
            self.pop_screen()
        self.push_screen(screen_type())

    def get_system_commands(self, screen: Screen[Any]) -> Iterable[SystemCommand]:
        yield from super().get_system_commands(screen)
        yield SystemCommand(
            "Arm or disarm", "Toggle whether the arm may move", self.action_toggle_arm
        )
        yield SystemCommand("Teach", "Teach a scene and its pose, then train", self.action_teach)
        yield SystemCommand(
            "Library", "Scenes, recordings and pictures; retrain, evaluate", self.action_library
        )
        yield SystemCommand("Settings", "Devices, joints and fusion windows", self.action_settings)
        # Textual's own "Keys" command shows the keys panel; this one is Servant's help screen
        yield SystemCommand("Help", "What each pane shows, and Servant's keys", self.action_help)
