"""The engine: owns the senses, the recognisers, the fusion policy and the arm; emits events.

One sense thread takes audio blocks into a ring (`loop.Hearing`) that cuts 5 s windows to be judged
(`judging`), lets the fusion policy tick and grabs a picture (`loop.Sight`) when the policy wants
one; so the events are a pure function of the input (a `ManualClock` demo is the same everywhere).
Subscribers are called on that thread (or the caller's: `label_unknown`, `retrain`, `arm`…): they
must be quick and not call `start`/`stop`. Faults are reported once (`DeviceStatus(ok=False)`,
`ErrorEvent`); the other senses carry on, a failed device reopened every `reopen_seconds`."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from servant_core.audio import DEFAULT_WINDOW_SECONDS
from servant_core.capture.source import (
    AudioSource,
    FrameSource,
    MonotonicClock,
    SampleSource,
)
from servant_core.engine.arm_commands import ArmCommands
from servant_core.engine.bus import Subscriber
from servant_core.engine.delegated import Delegated
from servant_core.engine.fusion_settings import fusion_config, reconfigured
from servant_core.engine.loop import SPECTRUM_FPS, SPECTRUM_SIZE, DeviceMakers
from servant_core.engine.parts import EngineParts
from servant_core.errors import ServantError
from servant_core.events import DeviceStatus, Notice
from servant_core.fusion import FusionPolicy
from servant_core.fusion.smoothing import SceneSmoother
from servant_core.library import SceneLibrary
from servant_core.recognisers import Recogniser
from servant_core.recognisers.base import windowed
from servant_core.senses import SAMPLE_SENSES
from servant_core.storage import data_dir

log = logging.getLogger(__name__)

# "What is this place?" is asked once the sound has named no taught place for this long: the
# paper's 30 s acoustic window, so a passing odd moment is never asked about.
ASK_AFTER_S = 30.0

NO_MODEL = (
    "no model yet: nothing can be recognised until two scenes are taught (teach mode, key t: "
    "six 5 s recordings and a few pictures of each, then Retrain) or trained from a library "
    "of recordings and pictures (`servant train LIBRARY`, then start servant again)"
)


def window_length(asked: float | None, acoustic: Recogniser | None) -> float:
    """The sound window's length in seconds: as asked, else the sound recogniser's, else the
    default."""
    own = windowed(acoustic).window_seconds if acoustic is not None else None
    return float(asked or own or DEFAULT_WINDOW_SECONDS)


class Engine(ArmCommands):
    """Senses → recognisers → fusion → decisions (→ poses → arm), as events to subscribers.

    Keyword-only parameters, each described beside it in `__init__`. Public API used by front ends:
    `subscribe`, `start`, `stop`, `running`, `join`, `run_until`, `status`, `audio_rate`,
    `record_window`, `take_picture`, `latest_scores`, `retrain`, `retrain_needed`, `label_unknown`,
    `set_arm`, `connect_arm`, `arm`, `disarm`, `link`, `pose_for`, `set_action_learner`,
    `apply_settings`, `note`.
    """

    # kept by its parts, used by front ends and tests as the engine's own
    acoustic = Delegated("_models")
    visual = Delegated("_models")
    sample_recognisers = Delegated("_models", "samples")
    fresh_methods = Delegated("_models")
    model_path = Delegated("_models", "path")
    retrain_needed = Delegated("_models")
    confidence_threshold = Delegated("_judge")
    fusion = Delegated("decisions", "policy")  # the fusion policy the decision pipeline feeds
    smoother = Delegated("decisions")

    retrain_reports_progress = True  # `retrain` takes `on_progress(done, total)`
    _thread: threading.Thread | None = None  # the sense thread, while started
    _opened = False  # the senses were opened (`start`, or a first `run_until`)
    sensor_port: str | None = None  # the settings' board the senses were opened on
    # the user's settings the engine was built on, the command line's overrides applied (a
    # front end starts from these, not from the file: `servant run --port P` keeps P)
    user_settings: Any = None
    _sensor_port_told: str | None = None
    # how Settings' camera and microphone are opened while running (None: they stay as built)
    device_makers: DeviceMakers | None = None

    def __init__(
        self,
        *,
        audio: AudioSource | None = None,
        camera: FrameSource | None = None,
        acoustic: Recogniser | None = None,
        visual: Recogniser | None = None,
        fusion: FusionPolicy | None = None,
        clock: Callable[[], float] | None = None,
        window_seconds: float | None = None,
        spectrum_fps: float = SPECTRUM_FPS,
        spectrum_size: int = SPECTRUM_SIZE,
        reopen_seconds: float = 2.0,
        library_root: str | Path | None = None,
        model_path: str | Path | None = None,
        fresh_methods: Mapping[str, str] | None = None,
        confidence_threshold: float | None = None,
        smoother: SceneSmoother | None = None,
        samples: Mapping[str, SampleSource] | None = None,
        sample_recognisers: Mapping[str, Recogniser] | None = None,
        ask_after_s: float = ASK_AFTER_S,
    ) -> None:
        """Each argument and its default: docs/engine.md, "The engine's arguments"."""
        self.audio = audio
        self.camera = camera
        self.samples = dict(samples or {})
        unknown = sorted(set(self.samples) - set(SAMPLE_SENSES))
        if unknown:
            raise ValueError(f"no sample sense named {', '.join(unknown)}")
        self.clock: Callable[[], float] = clock or MonotonicClock()
        self.window_seconds = window_length(window_seconds, acoustic)
        self.reopen_seconds = reopen_seconds
        self.library_root = Path(library_root) if library_root else None
        self.ask_after_s = ask_after_s
        parts = EngineParts.build(
            self,
            acoustic=acoustic,
            visual=visual,
            sample_recognisers=sample_recognisers or {},
            fusion=fusion,
            smoother=smoother,
            fresh_methods=fresh_methods or {},
            model_path=model_path,
            confidence_threshold=confidence_threshold,
            spectrum_fps=spectrum_fps,
            spectrum_size=spectrum_size,
        )
        # where every opinion becomes a decision (its policy is `fusion`, its smoother `smoother`)
        self.decisions = parts.decisions
        self._lock, self._bus, self._arm = parts.lock, parts.bus, parts.arm
        self._places, self._models, self._judge = parts.places, parts.models, parts.judge
        self._devices = parts.devices
        self._unknowns = self._places.store  # the kept windows, by id (benches keep their own)
        self._stop = threading.Event()
        self._life = threading.Lock()  # start and stop, one at a time
        self._finished = threading.Event()
        self._cleanups: list[Callable[[], None]] = []
        self._notes: list[str] = []  # said to every subscriber when the senses open

    # --- subscribers and status -------------------------------------------------------------

    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        """Call `callback(event)` for every event from now on; returns the way to unsubscribe."""
        return self._bus.subscribe(callback)

    @property
    def status(self) -> dict[str, DeviceStatus]:
        """The latest status of each device ("microphone", "camera", "servo")."""
        return self._bus.status

    def tell(self, message: str) -> None:
        """Say `message` as a `Notice` now, once."""
        self._bus.emit(Notice(self.clock(), message))

    def note(self, message: str) -> None:
        """Say `message` as a `Notice` now and again whenever the senses open: what a front end
        that subscribes later (a first start's "no model yet") must still hear."""
        self._notes.append(message)
        self._bus.emit(Notice(self.clock(), message))

    # --- life cycle ---------------------------------------------------------------------------

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Open the senses (a missing one is reported, not fatal) and start the sense thread."""
        with self._life:
            self._start()

    def _start(self) -> None:
        if self.running:
            return
        self._stop.clear()
        self._finished.clear()
        # An arm attached before anyone subscribed (the demo's) is said again to those who now
        # listen, or a front end would never learn that there is an arm to arm.
        servo = self._bus.status.get("servo")
        if servo is not None:
            self._bus.emit(servo)
        self._arm.emit_state()
        self._open_senses()
        self._arm.start()
        self._thread = threading.Thread(target=self._run, name="servant-senses", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the sense thread, close the senses and wait for a pose being sent; idempotent.
        A `start` still opening the senses on another thread (a front end quit at once) is
        waited for: a device must not be closed while it is being opened."""
        self._stop.set()
        with self._life:
            self._stop_started()

    def _stop_started(self) -> None:
        thread, self._thread = self._thread, None
        if thread is not None:
            thread.join()
        self._opened = False
        self._devices.close()
        self._arm.stop()
        while self._cleanups:
            self._cleanups.pop()()

    def add_cleanup(self, close: Callable[[], None]) -> None:
        """Run `close` when the engine stops (last added, first run): what it owns, it closes."""
        self._cleanups.append(close)

    def join(self, timeout: float | None = None) -> bool:
        """Wait until a finite audio source (a replay) has been played out; False on timeout."""
        return self._finished.wait(timeout)

    def run_until(self, t: float) -> None:
        """Run the senses on the caller's thread until the engine's clock reaches `t` (or the audio
        runs out). With a `ManualClock` this is fully deterministic; no thread is started."""
        if self.running:
            raise RuntimeError("run_until is for an engine that was not started")
        if not self._opened:
            self._open_senses()
        while self.clock() < t and not self._finished.is_set():
            self._step()

    def __enter__(self) -> Engine:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _open_senses(self) -> None:
        self._opened = True
        untrained = self._models.untrained()
        for message in [*self._notes, *([NO_MODEL] if untrained else [])]:
            self._bus.emit(Notice(self.clock(), message))
        self._bus.emit(self.fusion.state(self.clock()))
        self._devices.open()

    def _run(self) -> None:
        try:
            while not self._stop.is_set() and not self._finished.is_set():
                self._step()
        except Exception as exc:  # a bug must show, not silently stop the senses
            log.exception("the sense thread failed")
            self._bus.error(f"engine: the sense thread stopped ({type(exc).__name__}: {exc})")

    def _step(self, timeout: float = 0.05) -> None:
        """One turn of the senses (`SenseDevices.step`), then let fusion look."""
        if not self._devices.step(timeout, self._stop):
            self._finished.set()
            return
        self._judge.look(self._devices.sight)

    # --- the user's settings (the arm's commands: `arm_commands.ArmCommands`) ----------------

    def apply_settings(self, settings: Any) -> None:
        """Use the user's settings (`servant_core.settings.Settings`) from now on: the fusion
        windows (when they changed, the current window starts afresh), the confidence threshold,
        and the arm's port, protocol and joints (reconnected only when they changed; an arm
        attached with `set_arm`, like the demo's, stays). Call it off the UI thread: a
        controller that does not answer takes up to a second to say so."""
        with self._lock:
            self.fusion = reconfigured(self.fusion, fusion_config(settings))
            self.confidence_threshold = float(settings.confidence_threshold)
            state = self.fusion.state(self.clock())
        self._bus.emit(state)
        if self._arm.connected_here:
            self.connect_arm(settings.serial_port, settings.protocol, settings.joints)
        # A camera or microphone changed in Settings is opened now, not at the next start.
        # Compared with the settings the engine last took, so that one given on the command
        # line (`servant run --camera F`) stays until the user changes that field.
        before, self.user_settings = self.user_settings, settings
        if before is not None and self.device_makers is not None:
            self._devices.use(before, settings, self.device_makers)
        board = getattr(settings, "sensor_port", None)
        if board != self.sensor_port and board != self._sensor_port_told:
            self._sensor_port_told = board
            self.tell(
                f"sensor board {board or 'none'}: from the next start of Servant (the "
                "motion and ambient senses open with the engine)"
            )

    # --- what the front end asks for ----------------------------------------------------------

    @property
    def audio_rate(self) -> int:
        """The rate of the audio source (what `record_window` returns); 0 without audio."""
        return self._devices.audio_rate

    def record_window(
        self,
        seconds: float = DEFAULT_WINDOW_SECONDS,
        timeout: float | None = None,
        cancel: threading.Event | None = None,
    ) -> np.ndarray:
        """Record the next `seconds` of audio from now (blocks until they have arrived).

        Returns mono float32 at `audio_rate`. Raises ServantError without a working audio source,
        if the audio does not arrive within `timeout` (default: twice `seconds` plus 2 s), or at
        once when `cancel` is set or the engine stops meanwhile (nothing is returned then).
        """
        self._must_run()
        return self._devices.record_window(seconds, timeout, cancel)

    def record_samples(
        self,
        sense: str,
        seconds: float = DEFAULT_WINDOW_SECONDS,
        timeout: float | None = None,
        cancel: threading.Event | None = None,
    ) -> tuple[np.ndarray, int]:
        """Record the next `seconds` of a sample sense's readings from now: ((n, channels)
        float32, rows per second). ServantError if the sense is not in use or not working, or
        at once when `cancel` is set or the engine stops meanwhile."""
        self._must_run()
        return self._devices.record_samples(sense, seconds, timeout, cancel)

    def _must_run(self) -> None:
        if not self.running:
            raise ServantError("engine: not running; start it before recording")

    @property
    def sample_senses(self) -> list[str]:
        """The sample senses in use (with a source), by name."""
        return list(self.samples)

    def take_picture(self) -> np.ndarray:
        """A picture from the camera now (BGR uint8); ServantError if there is none."""
        return self._devices.take_picture()

    def latest_scores(self) -> dict[str, dict[str, float]]:
        """The last per-scene scores: {"acoustic": {scene: p}, "visual": {scene: p}}."""
        with self._lock:
            return self.decisions.latest()

    # --- learning (see `models` and `unknown_places`) -----------------------------------------

    def retrain(
        self,
        library: SceneLibrary | str | Path,
        on_progress: Callable[[int, int], None] | None = None,
    ) -> list[str]:
        """Refit copies of the recognisers on a scene library (sound, pictures, and each sample
        sense with logs in it), then swap them in (the senses keep running on the old ones
        meanwhile). A sense without a recogniser gets a new one of its
        `fresh_methods` method. Unreadable files are reported and skipped. A sense that cannot
        be trained (e.g. pictures of one scene only) is reported and keeps its recogniser while
        the other is retrained; if neither can be, the first reason is raised. `on_progress(done,
        total)` is called after each file read, recordings, pictures, then logs, on this
        thread. Returns the senses retrained ("audio", "image", …)."""
        if not isinstance(library, SceneLibrary):
            library = SceneLibrary.scan(library)
        return self._models.retrain(library, on_progress)

    def label_unknown(self, window_id: str, scene: str) -> Path:
        """Give an unknown window or picture (`UnknownScene`) the user's scene; return the file.

        The name must pass `place_names.place_name` (a known place named in another case is that
        place). The window is written atomically into the library (`library_root/<scene>/`), then
        folded into a copy of the recogniser that replaces it if it has `fold_in(X, scenes)`, else
        `retrain_needed` becomes True; with a `model_path`, the updated model is saved there. A
        refused name or a failed write is one ServantError; the window can still be labelled.
        """
        root = self.library_root or data_dir() / "library"
        known = self._models.known_scenes()
        kept, scene, path = self._places.write_label(window_id, scene, root, known)
        self._models.fold_in(kept, scene)
        return path
