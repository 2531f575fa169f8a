"""The engine: owns the senses, the recognisers, the fusion policy and the arm; emits events.

One sense thread does the work. It takes audio blocks into a ring (`loop.Hearing`), which cuts
consecutive windows (5 s) that are judged here, and — between blocks — lets the fusion policy
tick and grabs a picture (`loop.Sight`) whenever the policy wants one. Doing it all on one thread
keeps the order of events a pure function of the input: a demo run on a `ManualClock` gives the
same events on every machine. (The microphone's PortAudio callback runs on PortAudio's own thread
and only queues blocks.)

Its parts, by role: `bus` (subscribers, statuses, errors said once), `loop` (the devices side of
the sense loop), `learning` (retrain, fold-in, saving), `arm` (the link, poses, moves), and
`factories` (the demo's engine and the live one).

Subscribers are called on the sense thread (or on the thread calling `label_unknown`, `retrain`,
`arm`…): they must be quick and must not call back into `start`/`stop`. A front end posts the
event to its own loop.

Faults (a device gone, no frame, a corrupt replay file, a prediction that fails) are reported once
as `DeviceStatus(ok=False)` or `ErrorEvent`, and the engine carries on with the other senses,
reopening a failed device every `reopen_seconds`.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from servant_core.audio import DEFAULT_WINDOW_SECONDS, SILENT_DBFS, is_silent, resample
from servant_core.capture.source import (
    AudioSource,
    FrameSource,
    ManualClock,
    MonotonicClock,
    SampleSource,
)
from servant_core.engine import learning
from servant_core.engine.arm import ArmControl, PoseFor
from servant_core.engine.bus import EventBus, Subscriber
from servant_core.engine.learning import Kept, Unknowns
from servant_core.engine.loop import (
    SPECTRUM_FPS,
    SPECTRUM_SIZE,
    DeviceMakers,
    Feeling,
    Hearing,
    Sight,
)
from servant_core.errors import ServantError
from servant_core.events import (
    AcousticPrediction,
    Decision,
    DeviceStatus,
    Notice,
    Palette,
    SensePrediction,
    UnknownScene,
    VisualPrediction,
)
from servant_core.features.palette import dominant_colours
from servant_core.features.rows import UnusableWindow, checked_rows
from servant_core.fusion import (
    FusionConfig,
    FusionPolicy,
    LearnedFusion,
    SequentialFusion,
)
from servant_core.fusion.elsewhere import beside_open_sound, shown
from servant_core.fusion.pipeline import DecisionPipeline
from servant_core.fusion.smoothing import SceneSmoother
from servant_core.library import SceneLibrary
from servant_core.place_names import place_name
from servant_core.recognisers import FRESH_METHODS, UNKNOWN, Recogniser
from servant_core.recognisers.base import answers, knows_elsewhere
from servant_core.senses import SAMPLE_SENSES, SENSES
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


class Engine:
    """Senses → recognisers → fusion → decisions (→ poses → arm), as events to subscribers.

    Parameters
    - `audio`, `camera`: an `AudioSource` / `FrameSource` (see `servant_core.capture.source`),
      or None for a sense that is absent.
    - `acoustic`, `visual`: fitted recognisers (see `servant_core.recognisers.base`), or None.
    - `samples`: {sense: `SampleSource`} for the sample senses (`servant_core.senses`: motion,
      ambient), and `sample_recognisers`: {sense: fitted recogniser} to judge their windows.
    - `fusion`: a `FusionPolicy` (default: the paper's `SequentialFusion`).
    - `clock`: the engine's time in seconds (default: monotonic seconds since construction).
    - `window_seconds`: the window the acoustic recogniser judges (default: its own, else 5 s).
    - `library_root`: where `label_unknown` writes (default `data_dir()/"library"`).
    - `fresh_methods`: {sense: method} a retrain fits for a sense that has no recogniser yet
      (a first start, before anything was taught); default `FRESH_METHODS`.
    - `model_path`: the model file the recognisers came from. After a retrain or a fold-in the
      updated recognisers are saved back to it (atomically), so what the user taught survives a
      restart; None (the demo, or no model) keeps updates in memory only.
    - `confidence_threshold`: percent; the arm does not act on a decision less sure than this
      that the wearer is in its scene and not somewhere else (`fusion.elsewhere`; with no sense
      that knows elsewhere, the less sure sense's share) (None: no threshold of the engine's own).
    - `smoother`: a `SceneSmoother` that filters consecutive windows' probabilities, so that one
      odd window does not flip the scene (recognisers in percent that know no elsewhere; None:
      each window alone). It starts afresh whenever the acoustic recogniser changes. A sound
      recogniser that knows elsewhere is held steady by `steady_open` instead (two windows in a
      row name a place; a place named stays while two windows give it half on average).
    - `ask_after_s`: "What is this place?" (`UnknownScene` for the sound) once the sound has
      named no taught place for this long; its label is for all those windows (one recording
      of them in the library, each window learned).

    Public API used by front ends: `subscribe`, `start`, `stop`, `running`, `join`, `run_until`,
    `status`, `audio_rate`, `record_window`, `take_picture`, `latest_scores`, `retrain`,
    `retrain_needed`, `label_unknown`, `set_arm`, `connect_arm`, `arm`, `disarm`, `link`,
    `pose_for`, `set_action_learner`, `apply_settings`, `note`.
    """

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
        self.audio = audio
        self.camera = camera
        self.acoustic = acoustic
        self.visual = visual
        self.samples = dict(samples or {})
        self.sample_recognisers = dict(sample_recognisers or {})
        unknown = sorted(set(self.samples) - set(SAMPLE_SENSES))
        if unknown:
            raise ValueError(f"no sample sense named {', '.join(unknown)}")
        # where every opinion becomes a decision (its policy is `fusion`, its smoother `smoother`)
        self.decisions = DecisionPipeline(
            fusion if fusion is not None else SequentialFusion(),
            smoother,
            ["acoustic", "visual", *(SENSES[sense].role for sense in self.samples)],
        )
        self.clock: Callable[[], float] = clock or MonotonicClock()
        self.window_seconds = float(
            window_seconds or getattr(acoustic, "window_seconds", None) or DEFAULT_WINDOW_SECONDS
        )
        self.reopen_seconds = reopen_seconds
        self.library_root = Path(library_root) if library_root else None
        self.model_path = Path(model_path) if model_path else None
        self.fresh_methods = {**FRESH_METHODS, **(fresh_methods or {})}
        self.retrain_needed = False
        self.confidence_threshold = confidence_threshold
        self.ask_after_s = ask_after_s

        self._bus = EventBus(self.clock)
        self._arm = ArmControl(self._bus, reopen_seconds)
        self._make_senses(audio, camera, spectrum_fps, spectrum_size)
        self._init_state()

    def _make_senses(
        self,
        audio: AudioSource | None,
        camera: FrameSource | None,
        spectrum_fps: float,
        spectrum_size: int,
    ) -> None:
        """The threads' handles on each sense: hearing, sight and a feeling a sample sense."""
        reopen_seconds = self.reopen_seconds
        self._hearing = (
            Hearing(
                audio,
                self._bus,
                lambda window, rate: self._guarded(
                    "acoustic prediction", self._on_window, window, rate
                ),
                window_seconds=self.window_seconds,
                reopen_seconds=reopen_seconds,
                spectrum_fps=spectrum_fps,
                spectrum_size=spectrum_size,
            )
            if audio is not None
            else None
        )
        self._sight = Sight(camera, self._bus, reopen_seconds=reopen_seconds) if camera else None
        self._feelings = [
            Feeling(
                SAMPLE_SENSES[sense],
                source,
                self._bus,
                lambda name, window, rate: self._guarded(
                    f"{name} prediction", self._on_samples, name, window, rate
                ),
                window_seconds=self.window_seconds,
                reopen_seconds=reopen_seconds,
            )
            for sense, source in self.samples.items()
        ]

    def _init_state(self) -> None:
        """Locks, the run's lifecycle, and what the engine remembers between windows."""
        self._lock = threading.RLock()  # models, fusion, scores
        self._update_lock = threading.Lock()  # one model update (retrain, fold-in) at a time
        self._stop = threading.Event()
        self._life = threading.Lock()  # start and stop, one at a time
        self._finished = threading.Event()
        self._thread: threading.Thread | None = None
        self._cleanups: list[Callable[[], None]] = []
        self._notes: list[str] = []  # said to every subscriber when the senses open
        self._opened = False
        # Each sense's last opinion: (when, the scene it named or None).
        self._last_named: dict[str, tuple[float, str | None]] = {}
        self._unknowns = Unknowns()
        # the sound's last windows (and their rates) while it names no taught place, up to
        # `ask_after_s` of them: when "What is this place?" is asked and what its label is for
        self._unknown_windows: deque[tuple[np.ndarray, int]] = deque(
            maxlen=max(1, round(self.ask_after_s / self.window_seconds))
        )
        self._silent = False  # the last window was silence (its notice was given)
        # the predictions whose last window was skipped as unusable: told once, not each window
        self._skipping: set[str] = set()
        self.sensor_port: str | None = None  # the settings' board the senses were opened on
        # the user's settings the engine was built on, the command line's overrides applied (a
        # front end starts from these, not from the file: `servant run --port P` keeps P)
        self.user_settings: Any = None
        self._sensor_port_told: str | None = None
        # how Settings' camera and microphone are opened while running (None: they stay as built)
        self.device_makers: DeviceMakers | None = None
        self._next_audio: AudioSource | None = None  # swapped in on the sense thread

    @property
    def fusion(self) -> FusionPolicy:
        """The fusion policy the decision pipeline feeds."""
        return self.decisions.policy  # type: ignore[no-any-return]

    @fusion.setter
    def fusion(self, policy: FusionPolicy) -> None:
        self.decisions.policy = policy

    @property
    def smoother(self) -> SceneSmoother | None:
        return self.decisions.smoother

    # --- subscribers and status -------------------------------------------------------------

    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        """Call `callback(event)` for every event from now on; returns the way to unsubscribe."""
        return self._bus.subscribe(callback)

    @property
    def status(self) -> dict[str, DeviceStatus]:
        """The latest status of each device ("microphone", "camera", "servo")."""
        return self._bus.status

    def _emit(self, event: Any) -> None:
        self._bus.emit(event)

    def _error(self, message: str) -> None:
        self._bus.error(message)

    def tell(self, message: str) -> None:
        """Say `message` as a `Notice` now, once."""
        self._emit(Notice(self.clock(), message))

    def note(self, message: str) -> None:
        """Say `message` as a `Notice` now and again whenever the senses open: what a front end
        that subscribes later (a first start's "no model yet") must still hear."""
        self._notes.append(message)
        self._emit(Notice(self.clock(), message))

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
            self._emit(servo)
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
        self._close_senses()
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
        with self._lock:
            untrained = self.acoustic is None and self.visual is None
            untrained = untrained and not self.sample_recognisers
        for message in [*self._notes, *([NO_MODEL] if untrained else [])]:
            self._emit(Notice(self.clock(), message))
        self._emit(self.fusion.state(self.clock()))
        if self._hearing is not None:
            self._hearing.open()
        if self._sight is not None:
            self._sight.open()
        for feeling in self._feelings:
            feeling.open()

    def _close_senses(self) -> None:
        self._opened = False
        if self._hearing is not None:
            self._hearing.close()
        if self._sight is not None:
            self._sight.close()
        for feeling in self._feelings:
            feeling.close()

    # --- the sense thread ---------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while not self._stop.is_set() and not self._finished.is_set():
                self._step()
        except Exception as exc:  # a bug must show, not silently stop the senses
            log.exception("the sense thread failed")
            self._error(f"engine: the sense thread stopped ({type(exc).__name__}: {exc})")

    def _step(self, timeout: float = 0.05) -> None:
        """One turn: take an audio block if one comes within `timeout`, the readings of the sample
        senses, then let fusion look. Without working audio, the first sample sense waits."""
        hearing = self._hearing
        with self._lock:
            next_audio, self._next_audio = self._next_audio, None
        if next_audio is not None and hearing is not None:
            hearing.replace(next_audio)
        waited = False
        if hearing is not None and hearing.ok:
            if not hearing.listen(timeout):
                self._finished.set()
                return
            waited = True
        for feeling in self._feelings:
            feeling.feel(0.0 if waited else timeout)
            waited = waited or feeling.ok
        if not waited:
            if isinstance(self.clock, ManualClock) and not self._feelings:
                # Nothing moves a manual clock but a replay: without one there is no time.
                self._finished.set()
                return
            self._stop.wait(timeout)
            if hearing is not None:
                hearing.reopen_if_due(self.clock())
        if hearing is None and self._feelings and all(f.finished for f in self._feelings):
            self._finished.set()
            return
        self._look()

    def _guarded(self, what: str, fn: Callable[..., None], *args: Any) -> None:
        try:
            fn(*args)
        except UnusableWindow as error:
            if what not in self._skipping:  # one notice for a run of such windows
                self._skipping.add(what)
                self._emit(Notice(self.clock(), f"{error}; more are skipped without a word"))
            return
        except ServantError as error:
            self._error(str(error))
        except Exception as exc:  # e.g. a model trained on another window length: say it, go on
            log.debug("%s failed", what, exc_info=True)
            self._error(f"{what} failed: {type(exc).__name__}: {exc}")
        else:
            self._skipping.discard(what)

    def _on_window(self, window: np.ndarray, rate: int) -> None:
        with self._lock:
            acoustic = self.acoustic
        if acoustic is None:
            return
        t = self.clock()
        if is_silent(window):
            self._on_silence(acoustic, t)
            return
        self._silent = False
        model_rate = getattr(acoustic, "rate", rate)
        X = acoustic.featurize(resample(window, rate, model_rate)[None, :])
        unit = acoustic.confidence_unit
        open_ = knows_elsewhere(acoustic)
        with self._lock:
            scene, confidence, scores = self.decisions.hear(*_predict(acoustic, X), unit, open_)
            self.decisions.note("acoustic", scores, open_)
        known = scene != UNKNOWN
        self._emit(AcousticPrediction(t, scene if known else None, confidence, scores, unit))
        if self._unknown_held(known, window, rate):
            before = tuple(w for w, r in list(self._unknown_windows)[:-1] if r == rate)
            self._ask_label(Kept("audio", window, rate, before), scores, t)
        with self._lock:
            events = self._judged("audio", scene if known else None, confidence, t, scores)
        self._handle(events)

    def _on_silence(self, acoustic: Recogniser, t: float) -> None:
        """A silent window (a muted microphone, digital zeros) names no place, for the arm too:
        a recogniser asked about silence still picks a taught place. It is not asked about
        either; what the sound believed before the silence is forgotten."""
        if not self._silent:  # one notice for a run of silent windows
            self._silent = True
            self._emit(
                Notice(
                    t,
                    f"microphone: silence (below {SILENT_DBFS:.0f} dBFS) names no place until "
                    "sound comes back; is the microphone muted?",
                )
            )
        scores = {str(s): 0.0 for s in acoustic.scenes_}
        with self._lock:
            self._forget_windows()
            self.decisions.scores["acoustic"] = scores
        self._emit(AcousticPrediction(t, None, 0.0, scores, acoustic.confidence_unit))
        with self._lock:
            events = self._judged("audio", None, 0.0, t, scores)
        self._handle(events)

    def _judged(
        self, sense: str, scene: str | None, confidence: float, t: float, scores: dict[str, float]
    ) -> list[Any]:
        """A sense's judgement to the decision pipeline (called under `_lock`)."""
        self._last_named[sense] = (t, scene)
        return self.decisions.tell(sense, scene, confidence, t, scores)

    def _on_samples(self, sense: str, window: np.ndarray, rate: int) -> None:
        with self._lock:
            recogniser = self.sample_recognisers.get(sense)
        if recogniser is None:
            return
        t = self.clock()
        rows = learning.resampled_rows(window, rate, int(getattr(recogniser, "rate", rate)))
        scene, confidence, scores = _predict(recogniser, recogniser.featurize([rows]))
        known = scene != UNKNOWN
        with self._lock:
            self.decisions.note(SENSES[sense].role, scores, knows_elsewhere(recogniser))
        figure, unit = self._shown(scene if known else None, confidence, scores, recogniser)
        self._emit(SensePrediction(t, sense, scene if known else None, figure, scores, unit))
        if not known and not self._named_elsewhere(sense, t):
            self._ask_label(Kept(sense, rows, int(getattr(recogniser, "rate", rate))), scores, t)
        with self._lock:
            events = self._judged(sense, scene if known else None, confidence, t, scores)
        self._handle(events)

    def _named_elsewhere(self, sense: str, t: float) -> bool:
        """Whether another sense named a place within the last two windows. A sample sense
        (motion, ambient) that does not know a place the sound or the camera knows is not
        worth asking the wearer about: they know where they are, and so does Servant."""
        recent = t - 2 * self.window_seconds
        with self._lock:
            named = list(self._last_named.items())
        return any(other != sense and scene and when >= recent for other, (when, scene) in named)

    def _forget_windows(self) -> None:
        """A new acoustic model: what the old one believed about past windows means nothing (and
        a stretch just labelled is not asked about again)."""
        self.decisions.forget()
        self._unknown_windows.clear()

    def _shown(
        self, scene: str | None, confidence: float, scores: dict[str, float], recogniser: Any
    ) -> tuple[float, str | None]:
        """The figure and unit a sense's prediction is shown with (`fusion.elsewhere.shown`)."""
        with self._lock:  # the sound's model, not its last window: from the first picture on
            acoustic = self.acoustic
        beside = beside_open_sound(acoustic, recogniser)
        return shown(scene, confidence, recogniser.confidence_unit, scores, beside)

    def _unknown_held(self, known: bool, window: np.ndarray, rate: int) -> bool:
        """Whether the sound has named no taught place for `ask_after_s` (this window included):
        only then is the wearer asked "What is this place?", and at each window while it holds
        (the app limits how often the question is shown). The windows of that stretch are kept
        (`_unknown_windows`): the label the wearer gives is for all of them, not the last 5 s
        alone, so the place is learned from as much as teach mode asks for (`TEACH_WINDOWS`,
        30 s)."""
        if known:
            self._unknown_windows.clear()
            return False
        self._unknown_windows.append((window, rate))
        return len(self._unknown_windows) == self._unknown_windows.maxlen

    def _look(self) -> None:
        t = self.clock()
        with self._lock:
            events = self.decisions.tick(t)
            wants = self._sight is not None and self.decisions.wants_picture(t)
        self._handle(events)
        self._arm.check(t)
        if not wants:
            return
        assert self._sight is not None
        frame = self._sight.grab(t)
        if frame is not None:
            self._guarded("visual prediction", self._on_picture, frame, t)

    def _on_picture(self, frame: np.ndarray, t: float) -> None:
        with self._lock:
            visual = self.visual
        if visual is None:
            self._emit(Palette(t, *dominant_colours(frame)))
            return
        X = visual.featurize([frame])
        scene, confidence, scores = _predict(visual, X)
        known = scene != UNKNOWN
        with self._lock:
            self.decisions.note("visual", scores, knows_elsewhere(visual))
            events = self._judged("image", scene if known else None, confidence, t, scores)
        figure, unit = self._shown(scene if known else None, confidence, scores, visual)
        self._emit(VisualPrediction(t, scene if known else None, figure, scores, unit))
        # The decision (and the arm's move) first; the palette is only for show.
        self._handle(events)
        matched = visual.matched_palette(X)[0] if hasattr(visual, "matched_palette") else None
        self._emit(Palette(t, *dominant_colours(frame), scene if known else None, matched))
        if not known:
            self._ask_label(Kept("image", frame), scores, t)

    def _handle(self, events: list[Any]) -> None:
        for event in events:
            if not isinstance(event, Decision) or event.scene is None:
                self._emit(event)
                continue
            scene = event.scene
            with self._lock:
                unit = decision_unit(self.acoustic, self.visual)
                event, roles = self.decisions.settle(event)
                latest = self.decisions.latest()  # one snapshot for the figure and the arm
                open_roles = set(self.decisions.open_roles)
            event = dataclasses.replace(event, confidence_unit=unit)
            self._emit(event)
            if event.scene is None:
                continue
            self._arm.act(
                scene,
                latest,
                self.confidence_threshold,
                roles,
                open_roles,
                event.confidence / 100.0 if event.not_elsewhere else None,
            )

    # --- the arm (see `arm.ArmControl`) -------------------------------------------------------

    @property
    def link(self) -> Any:
        """The attached servo link, or None."""
        return self._arm.link

    @property
    def pose_for(self) -> PoseFor | None:
        """What turns a decided scene into a pose (`set_action_learner`), or None."""
        return self._arm.pose_for

    def set_action_learner(self, pose_for: PoseFor | None) -> None:
        """Attach what turns a detected scene into a pose: a callable
        (scene, scores, confidence) → {joint: degrees} or None, e.g. `ActionLearner.pose_for`.
        `scores` are the latest per-sense scene scores; `confidence` (percent) is the smaller of
        the two senses' probabilities for the scene. None detaches it."""
        self._arm.pose_for = pose_for

    def set_arm(self, link: Any, why_none: str = "servo: no arm attached") -> None:
        """Attach a servo link (`servant_core.servo.link`: `.arm()`, `.disarm()`, `.armed`,
        `.move_to(pose)`, `.status()`), or None to detach it (`why_none` says why). The link
        enforces limits and rate. A link attached here is not closed by the engine."""
        self._arm.set_arm(link, why_none)

    def connect_arm(self, port: str | None, protocol: str, joints: Sequence[Any]) -> None:
        """Open the arm the settings name (disarmed) and attach it, closing the one this method
        attached before; the engine closes it when it stops. A missing port or a controller that
        does not answer is reported as the servo's status, never raised: the senses go on.
        Asking again for the same port, protocol and joints keeps the link as it is."""
        self._arm.connect(port, protocol, joints)

    def arm(self) -> None:
        """Allow the arm to move (delegates to the link); ServantError if no arm is attached."""
        self._arm.arm()

    def disarm(self) -> None:
        """Forbid the arm to move; does nothing when no arm is attached (safe to call always)."""
        self._arm.disarm()

    def read_arm_pose(self) -> dict[str, float]:
        """The arm's joints' angles as its controller reports them, armed or not (teach mode's
        "Use the arm's pose"); ServantError when there is no arm or it says nothing."""
        return self._arm.read_pose()

    def apply_settings(self, settings: Any) -> None:
        """Use the user's settings (`servant_core.settings.Settings`) from now on: the fusion
        windows (when they changed, the current window starts afresh), the confidence threshold,
        and the arm's port, protocol and joints (reconnected only when they changed; an arm
        attached with `set_arm`, like the demo's, stays). Call it off the UI thread: a
        controller that does not answer takes up to a second to say so."""
        config = fusion_config(settings)
        with self._lock:
            # the policies of servant_core.fusion; unchanged windows keep the current one open
            if getattr(self.fusion, "config", config) != config:
                if isinstance(self.fusion, LearnedFusion):  # the net stays what it learned
                    self.fusion = LearnedFusion(config, self.fusion.net)
                else:
                    policy: Any = type(self.fusion)
                    self.fusion = policy(config)
            self.confidence_threshold = float(settings.confidence_threshold)
            state = self.fusion.state(self.clock())
        self._emit(state)
        if self._arm.connected_here:
            self.connect_arm(settings.serial_port, settings.protocol, settings.joints)
        self._use_devices(settings)
        board = getattr(settings, "sensor_port", None)
        if board != self.sensor_port and board != self._sensor_port_told:
            self._sensor_port_told = board
            self._emit(
                Notice(
                    self.clock(),
                    f"sensor board {board or 'none'}: from the next start of Servant (the "
                    "motion and ambient senses open with the engine)",
                )
            )

    def _use_devices(self, settings: Any) -> None:
        """A camera or microphone changed in Settings is opened now, not at the next start.
        Compared with the settings the engine last took, so that one given on the command line
        (`servant run --camera F`) stays until the user changes that field."""
        before, self.user_settings = self.user_settings, settings
        makers = self.device_makers
        if before is None or makers is None:
            return
        if settings.camera != before.camera and self._sight is not None:
            self._sight.replace(makers.camera(settings.camera))
        if settings.audio_device != before.audio_device and self._hearing is not None:
            with self._lock:
                self._next_audio = makers.microphone(settings.audio_device)

    # --- what the front end asks for ----------------------------------------------------------

    @property
    def audio_rate(self) -> int:
        """The rate of the audio source (what `record_window` returns); 0 without audio."""
        return self._hearing.rate if self._hearing is not None else 0

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
        if not self.running:
            raise ServantError("engine: not running; start it before recording")
        if self._hearing is None:
            raise ServantError("microphone: no sound to record; check the microphone (see status)")
        window = self._hearing.record(seconds, timeout, cancel)
        if is_silent(window):  # a place taught as silence would be named wherever it is quiet
            raise ServantError(
                f"microphone: the recording is silence (below {SILENT_DBFS:.0f} dBFS) and was not "
                "kept; unmute or check the microphone, then record again"
            )
        return window

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
        if not self.running:
            raise ServantError("engine: not running; start it before recording")
        for feeling in self._feelings:
            if feeling.sense.name == sense:
                return feeling.record(seconds, timeout, cancel), feeling.source.rate
        raise ServantError(f"{sense}: not in use; start with its sensor (e.g. --imu PORT)")

    @property
    def sample_senses(self) -> list[str]:
        """The sample senses in use (with a source), by name."""
        return list(self.samples)

    def take_picture(self) -> np.ndarray:
        """A picture from the camera now (BGR uint8); ServantError if there is none."""
        if self._sight is None:
            raise ServantError("camera: none in use; start with a camera to take pictures")
        frame = self._sight.grab(self.clock())
        if frame is None:
            message = self._bus.status.get("camera")
            raise ServantError(message.message if message else "camera: no picture")
        return frame

    def latest_scores(self) -> dict[str, dict[str, float]]:
        """The last per-scene scores: {"acoustic": {scene: p}, "visual": {scene: p}}."""
        with self._lock:
            return self.decisions.latest()

    # --- learning (see `learning`) ------------------------------------------------------------

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
        with self._update_lock:
            with self._lock:
                current = self._recognisers_by_sense()
            fitted, failures = learning.retrained(
                library,
                current,
                self.fresh_methods,
                self.window_seconds,
                self._report_error,
                on_progress,
            )
            if not fitted:
                if failures:
                    raise failures[0]
                return []
            for failure in failures:
                self._error(str(failure))
            senses = list(fitted)
            with self._lock:
                if "audio" in fitted:
                    self.acoustic = fitted.pop("audio")
                    self._forget_windows()
                self.visual = fitted.pop("image", self.visual)
                self.sample_recognisers.update(fitted)
                self.retrain_needed = False
            self._relearn_fusion(library)
            self._save_models()
        return senses

    def _relearn_fusion(self, library: SceneLibrary) -> None:
        """The learned policy's net, taught again on the retrained recognisers (called under
        `_update_lock`); too little taught, the parallel policy decides meanwhile, and a Notice
        says why. The rule policies learn nothing."""
        with self._lock:
            if not isinstance(self.fusion, LearnedFusion):
                return
            recognisers = self._recognisers_by_sense()
        net, why = learning.library_fusion_net(
            library, recognisers, self.window_seconds, self._report_error
        )
        with self._lock:
            self.fusion = LearnedFusion(self.fusion.config, net)
            state = self.fusion.state(self.clock())
        self._emit(state)
        if net is None:
            self._emit(Notice(self.clock(), f"learned fusion: {why}; the parallel policy decides"))

    def _recognisers_by_sense(self) -> dict[str, Recogniser]:
        found = {"audio": self.acoustic, "image": self.visual, **self.sample_recognisers}
        return {sense: model for sense, model in found.items() if model is not None}

    def _known_scenes(self) -> list[str]:
        """The places the recognisers know, which a label may name in another case."""
        with self._lock:
            models = list(self._recognisers_by_sense().values())
        return sorted({str(s) for model in models for s in getattr(model, "scenes_", [])})

    def _report_error(self, error: ServantError) -> None:
        self._error(str(error))

    def _ask_label(self, kept: Kept, scores: dict[str, float], t: float) -> None:
        window_id = self._unknowns.keep(kept)
        nearest = max(scores, key=lambda s: scores[s]) if scores else None
        self._emit(UnknownScene(t, kept.sense, nearest, window_id))

    def label_unknown(self, window_id: str, scene: str) -> Path:
        """Give the scene the user named to an unknown window, picture or sample sense's window
        (from `UnknownScene`).

        The name must pass `place_names.place_name` (one naming a known place in another case
        is that place). It is written into the library (`library_root/<scene>/`, atomically),
        then folded into a copy of the recogniser that replaces it, if it has `fold_in(X,
        scenes)`; otherwise `retrain_needed` becomes True. With a `model_path`, the updated model
        is saved there. Returns the file written. A refused name or a failed write is one
        ServantError, and the window can still be labelled.
        """
        root = self.library_root or data_dir() / "library"
        scene = place_name(scene, root, self._known_scenes())
        # out of the store only once written: a label whose write fails can be given again
        with self._unknowns.labelling(window_id) as kept:
            path = learning.write_labelled(root, scene, window_id, kept)
        with self._update_lock:
            with self._lock:
                recogniser = self._recognisers_by_sense().get(kept.sense)
                if recogniser is None or not hasattr(recogniser, "fold_in"):
                    self.retrain_needed = True
                    return path
            model = learning.folded_in(recogniser, kept, scene)
            with self._lock:
                if kept.sense == "audio":
                    self.acoustic = model
                    self._forget_windows()
                elif kept.sense == "image":
                    self.visual = model
                else:
                    self.sample_recognisers[kept.sense] = model
            self._save_models()
        return path

    def _save_models(self) -> None:
        """Write the current recognisers to `model_path` (called under `_update_lock`)."""
        if self.model_path is None:
            return
        with self._lock:
            models = {"acoustic": self.acoustic, "visual": self.visual}
            models.update({SENSES[s].role: m for s, m in self.sample_recognisers.items()})
            net = getattr(self.fusion, "net", None)
        learning.save_models(self.model_path, models, self._report_error, net)


def fusion_config(settings: Any) -> FusionConfig:
    """The fusion windows of the user's settings (`servant_core.settings.Settings`)."""
    return FusionConfig(
        acoustic_window_s=settings.acoustic_window_s,
        confirm_window_s=settings.confirm_window_s,
        pictures_needed=settings.pictures_needed,
        picture_interval_s=settings.picture_interval_s,
    )


def decision_unit(*recognisers: Recogniser | None) -> str | None:
    """The unit of an average of these recognisers' confidences (a decision's): theirs when they
    all share one, as percentages do; else None (the paper's eq. 1 and eq. 2 share none)."""
    units = {getattr(r, "confidence_unit", None) for r in recognisers}
    return units.pop() if len(units) == 1 else None


def _predict(recogniser: Recogniser, X: np.ndarray) -> tuple[str, float, dict[str, float]]:
    """(scene or UNKNOWN, confidence, {scene: probability}) for a single featurized row;
    `UnusableWindow` when the row is not finite numbers."""
    checked_rows(X, f"{recogniser.sense} prediction")
    names, confidences, probabilities = answers(recogniser, X)
    return (
        str(names[0]),
        float(confidences[0]),
        {s: float(p) for s, p in zip(recogniser.scenes_, probabilities[0], strict=True)},
    )
