"""The engine: owns the senses, the recognisers, the fusion policy and the arm; emits events.

One sense thread does the work. It takes audio blocks from the audio source into a ring buffer,
makes a spectrum frame ~30 times per second of audio, cuts consecutive windows (5 s) and predicts
each, and — between blocks — lets the fusion policy tick and grabs a picture whenever the policy
wants one. Doing it all on one thread keeps the order of events a pure function of the input: a
demo run on a `ManualClock` gives the same events on every machine. (The microphone's PortAudio
callback runs on PortAudio's own thread and only queues blocks.)

Subscribers are called on the sense thread (or on the thread calling `label_unknown`, `retrain`,
`arm`…): they must be quick and must not call back into `start`/`stop`. A front end posts the
event to its own loop.

Faults (a device gone, no frame, a corrupt replay file, a prediction that fails) are reported once
as `DeviceStatus(ok=False)` or `ErrorEvent`, and the engine carries on with the other senses,
reopening a failed device every `reopen_seconds`.

Factories for front ends: `build_demo_engine` (the synthesised walk) and `build_live_engine`
(microphone, camera, a trained model file, the user's settings, the arm and its taught poses).
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import re
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from servant_core.audio import DEFAULT_RATE, DEFAULT_WINDOW_SECONDS, resample, write_wav
from servant_core.capture.ring import RingBuffer
from servant_core.capture.source import AudioSource, FrameSource, ManualClock, MonotonicClock
from servant_core.errors import ServantError
from servant_core.events import (
    AcousticPrediction,
    ArmState,
    Decision,
    DeviceStatus,
    ErrorEvent,
    Event,
    Notice,
    Palette,
    SpectrumFrame,
    UnknownScene,
    VisualPrediction,
)
from servant_core.features.palette import dominant_colours
from servant_core.fusion import POLICIES, FusionConfig, FusionPolicy, SequentialFusion
from servant_core.fusion.smoothing import STEADY_FLOOR, STEADY_STAY, SceneSmoother
from servant_core.library import SceneLibrary, featurize_recordings, read_pictures
from servant_core.modelfile import save_model
from servant_core.recognisers import FRESH_METHODS, UNKNOWN, Recogniser, make_recogniser
from servant_core.storage import atomic_write_bytes, data_dir

log = logging.getLogger(__name__)


Subscriber = Callable[[Event], None]
Pose = Mapping[str, float]
PoseFor = Callable[[str, dict[str, dict[str, float]], float], Pose | None]

SPECTRUM_SIZE = 2048
SPECTRUM_FPS = 30.0
RING_SECONDS = 30.0  # what the ring holds: a window being cut while teach mode records 5 s
UNKNOWN_KEPT = 16  # unknown windows/pictures kept for the user to label, the oldest dropped first
NO_MODEL = (
    "no model yet: nothing can be recognised until two scenes are taught (teach mode, key t: "
    "5 s of sound and a few pictures of each, then Retrain) or a model is given "
    "(`servant train LIBRARY -o model.npz`, then --model)"
)
NO_POSE = "arm: no pose taught yet, so it stays put; teach one in teach mode (key t), then Train"


def spectrum_db(samples: np.ndarray, rate: int) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies in Hz, magnitude in dB re full scale) of a Hann-windowed stretch of samples.

    A full-scale sine reads 0 dB; silence is floored at −120 dB.
    """
    n = len(samples)
    hann = np.hanning(n)
    magnitude = np.abs(np.fft.rfft(samples * hann)) * 2.0 / hann.sum()
    return np.fft.rfftfreq(n, 1.0 / rate), 20.0 * np.log10(np.maximum(magnitude, 1e-6))


@dataclass
class _Kept:
    """An unknown window or picture, held until the user labels it."""

    sense: str  # "audio" | "image"
    data: np.ndarray
    rate: int = 0


class Engine:
    """Senses → recognisers → fusion → decisions (→ poses → arm), as events to subscribers.

    Parameters
    - `audio`, `camera`: an `AudioSource` / `FrameSource` (see `servant_core.capture.source`),
      or None for a sense that is absent.
    - `acoustic`, `visual`: fitted recognisers (see `servant_core.recognisers.base`), or None.
    - `fusion`: a `FusionPolicy` (default: the paper's `SequentialFusion`).
    - `clock`: the engine's time in seconds (default: monotonic seconds since construction).
    - `window_seconds`: the window the acoustic recogniser judges (default: its own, else 5 s).
    - `library_root`: where `label_unknown` writes (default `data_dir()/"library"`).
    - `fresh_methods`: {sense: method} a retrain fits for a sense that has no recogniser yet
      (a first start, before anything was taught); default `FRESH_METHODS`.
    - `model_path`: the model file the recognisers came from. After a retrain or a fold-in the
      updated recognisers are saved back to it (atomically), so what the user taught survives a
      restart; None (the demo, or no model) keeps updates in memory only.
    - `confidence_threshold`: percent; the arm does not act on a decision whose scene the less
      sure sense gives less than this (None: no threshold of the engine's own).
    - `smoother`: a `SceneSmoother` that filters consecutive windows' probabilities, so that one
      odd window does not flip the scene (recognisers in percent only; None: each window alone).
      It starts afresh whenever the acoustic recogniser changes.

    Public API used by front ends: `subscribe`, `start`, `stop`, `running`, `join`, `run_until`,
    `status`, `audio_rate`, `record_window`, `take_picture`, `latest_scores`, `retrain`,
    `retrain_needed`, `label_unknown`, `set_arm`, `connect_arm`, `arm`, `disarm`,
    `set_action_learner`, `apply_settings`, `note`.
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
    ) -> None:
        self.audio = audio
        self.camera = camera
        self.acoustic = acoustic
        self.visual = visual
        self.fusion: FusionPolicy = fusion if fusion is not None else SequentialFusion()
        self.clock: Callable[[], float] = clock or MonotonicClock()
        self.window_seconds = float(
            window_seconds or getattr(acoustic, "window_seconds", None) or DEFAULT_WINDOW_SECONDS
        )
        self.spectrum_fps = spectrum_fps
        self.spectrum_size = spectrum_size
        self.reopen_seconds = reopen_seconds
        self.library_root = Path(library_root) if library_root else None
        self.model_path = Path(model_path) if model_path else None
        self.fresh_methods = dict(fresh_methods or FRESH_METHODS)
        self.retrain_needed = False
        self.confidence_threshold = confidence_threshold
        self.smoother = smoother

        self._subscribers: list[Subscriber] = []
        self._subscribers_lock = threading.Lock()
        self._status: dict[str, DeviceStatus] = {}
        self._reported_errors: set[str] = set()
        self._lock = threading.RLock()  # models, fusion, scores, unknowns
        self._update_lock = threading.Lock()  # one model update (retrain, fold-in) at a time
        self._camera_lock = threading.Lock()
        self._stop = threading.Event()
        self._life = threading.Lock()  # start and stop, one at a time
        self._finished = threading.Event()
        self._thread: threading.Thread | None = None
        self._arm_pool: ThreadPoolExecutor | None = None
        self._link: Any = None
        self._pose_for: PoseFor | None = None
        self._arm_spec: tuple[Any, ...] | None = None  # (port, protocol, joints) of connect_arm
        self._cleanups: list[Callable[[], None]] = []
        self._notes: list[str] = []  # said to every subscriber when the senses open

        self._opened = False
        self._ring: RingBuffer | None = None
        self._audio_ok = False
        self._audio_retry_at = 0.0
        self._camera_ok = False
        self._camera_retry_at = 0.0
        self._arm_checked_at = 0.0
        self._next_window_end = 0
        self._next_spectrum_at = 0
        self._scores: dict[str, dict[str, float]] = {"acoustic": {}, "visual": {}}
        self._unknown: OrderedDict[str, _Kept] = OrderedDict()
        self._unknown_count = 0

    # --- subscribers and status -------------------------------------------------------------

    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        """Call `callback(event)` for every event from now on; returns the way to unsubscribe."""
        with self._subscribers_lock:
            self._subscribers.append(callback)

        def unsubscribe() -> None:
            with self._subscribers_lock:
                if callback in self._subscribers:
                    self._subscribers.remove(callback)

        return unsubscribe

    def _emit(self, event: Event) -> None:
        with self._subscribers_lock:
            subscribers = list(self._subscribers)
        for callback in subscribers:
            try:
                callback(event)
            except Exception:  # a broken subscriber must not stop the senses
                log.exception("event subscriber %r failed", callback)

    @property
    def status(self) -> dict[str, DeviceStatus]:
        """The latest status of each device ("microphone", "camera", "servo")."""
        return dict(self._status)

    def _report(self, device: str, ok: bool, message: str) -> None:
        """Emit a DeviceStatus when a device's state changes: a fault is said once, however it then
        fails to reopen, until the device works again."""
        previous = self._status.get(device)
        if previous is not None and previous.ok == ok and (previous.message == message or not ok):
            return
        status = DeviceStatus(self.clock(), device, ok, message)
        self._status[device] = status
        self._emit(status)

    def _error(self, message: str) -> None:
        """Emit an ErrorEvent the first time this message occurs."""
        if message in self._reported_errors:
            return
        self._reported_errors.add(message)
        self._emit(ErrorEvent(self.clock(), message))

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
        servo = self._status.get("servo")
        if servo is not None:
            self._emit(servo)
        self._emit_arm_state()
        self._open_senses()
        self._arm_pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="servant-arm")
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
        pool, self._arm_pool = self._arm_pool, None
        if pool is not None:
            pool.shutdown(wait=True)
        self._close_arm()
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

    def note(self, message: str) -> None:
        """Say `message` as a `Notice` now and again whenever the senses open: what a front end
        that subscribes later (a first start's "no model yet") must still hear."""
        self._notes.append(message)
        self._emit(Notice(self.clock(), message))

    def _open_senses(self) -> None:
        self._opened = True
        with self._lock:
            untrained = self.acoustic is None and self.visual is None
        for message in [*self._notes, *([NO_MODEL] if untrained else [])]:
            self._emit(Notice(self.clock(), message))
        self._emit(self.fusion.state(self.clock()))
        if self.audio is not None:
            self._open_audio()
        if self.camera is not None:
            with self._camera_lock:
                self._open_camera()

    def _close_senses(self) -> None:
        self._opened = False
        if self.audio is not None:
            self.audio.close()
            self._audio_ok = False
        if self.camera is not None:
            with self._camera_lock:
                self.camera.close()
                self._camera_ok = False

    def _open_audio(self) -> None:
        assert self.audio is not None
        try:
            self.audio.open()
        except ServantError as error:
            self._audio_ok = False
            self._audio_retry_at = self.clock() + self.reopen_seconds
            self._report("microphone", False, str(error))
            return
        rate = self.audio.rate
        if self._ring is None or self._ring.capacity != int(rate * RING_SECONDS):
            self._ring = RingBuffer(int(rate * RING_SECONDS))
        # Windows start afresh after (re)opening: never stitch audio from both sides of a gap.
        self._next_window_end = self._ring.total + int(round(self.window_seconds * rate))
        self._next_spectrum_at = self._ring.total
        self._audio_ok = True
        note = getattr(self.audio, "rate_note", None)
        self._report("microphone", True, note or f"{self.audio.name}: listening at {rate} Hz")

    def _open_camera(self) -> None:
        assert self.camera is not None
        try:
            self.camera.open()
        except ServantError as error:
            self._camera_fault(error)
            return
        self._camera_ok = True
        self._report("camera", True, f"{self.camera.name}: ready")

    def _camera_fault(self, error: ServantError) -> None:
        assert self.camera is not None
        self.camera.close()
        self._camera_ok = False
        self._camera_retry_at = self.clock() + self.reopen_seconds
        self._report("camera", False, str(error))

    # --- the sense thread ---------------------------------------------------------------------

    def _run(self) -> None:
        try:
            while not self._stop.is_set() and not self._finished.is_set():
                self._step()
        except Exception as exc:  # a bug must show, not silently stop the senses
            log.exception("the sense thread failed")
            self._error(f"engine: the sense thread stopped ({type(exc).__name__}: {exc})")

    def _step(self, timeout: float = 0.05) -> None:
        """One turn: take an audio block if one comes within `timeout`, then let fusion look."""
        audio = self.audio
        if audio is not None and self._audio_ok:
            try:
                block = audio.read(timeout)
            except ServantError as error:
                self._audio_fault(error)
                block = None
            if block is not None and len(block):
                self._on_block(block)
            elif audio.exhausted:
                self._report("microphone", False, f"{audio.name}: finished")
                self._finished.set()
                return
        else:
            if isinstance(self.clock, ManualClock):
                # Nothing moves a manual clock but the audio: without audio there is no time.
                self._finished.set()
                return
            self._stop.wait(timeout)
            if audio is not None and self.clock() >= self._audio_retry_at:
                self._open_audio()
        self._look()

    def _audio_fault(self, error: ServantError) -> None:
        """A live device that stopped is closed and reopened later; a replay skips the bad file."""
        assert self.audio is not None
        if not getattr(self.audio, "live", False):
            self._error(str(error))
            return
        self._report("microphone", False, str(error))
        self.audio.close()
        self._audio_ok = False
        self._audio_retry_at = self.clock() + self.reopen_seconds

    def _on_block(self, block: np.ndarray) -> None:
        assert self._ring is not None and self.audio is not None
        ring, rate = self._ring, self.audio.rate
        ring.append(block)
        total = ring.total
        if (
            self.spectrum_fps > 0
            and total >= self._next_spectrum_at
            and total >= self.spectrum_size
        ):
            freqs, db = spectrum_db(ring.latest(self.spectrum_size), rate)
            self._emit(SpectrumFrame(self.clock(), freqs, db))
            hop = max(1, int(rate / self.spectrum_fps))
            self._next_spectrum_at = (total // hop + 1) * hop
        size = int(round(self.window_seconds * rate))
        while total >= self._next_window_end:
            end = self._next_window_end
            self._next_window_end += size
            self._guarded("acoustic prediction", self._on_window, ring.read(end - size, end), rate)

    def _guarded(self, what: str, fn: Callable[..., None], *args: Any) -> None:
        try:
            fn(*args)
        except ServantError as error:
            self._error(str(error))
        except Exception as exc:  # e.g. a model trained on another window length: say it, go on
            log.debug("%s failed", what, exc_info=True)
            self._error(f"{what} failed: {type(exc).__name__}: {exc}")

    def _on_window(self, window: np.ndarray, rate: int) -> None:
        with self._lock:
            acoustic = self.acoustic
        if acoustic is None:
            return
        t = self.clock()
        model_rate = getattr(acoustic, "rate", rate)
        X = acoustic.featurize(resample(window, rate, model_rate)[None, :])
        scene, confidence, scores = _predict(acoustic, X)
        unit = acoustic.confidence_unit
        if self.smoother is not None and unit == "%":
            scene, confidence, scores = self._smoothed(scene, scores)
        with self._lock:
            self._scores["acoustic"] = scores
        known = scene != UNKNOWN
        self._emit(AcousticPrediction(t, scene if known else None, confidence, scores, unit))
        if not known:
            self._ask_label("audio", _Kept("audio", window, rate), scores, t)
        with self._lock:
            events = self.fusion.on_acoustic(scene if known else None, confidence, t)
        self._handle(events)

    def _forget_windows(self) -> None:
        """A new acoustic model: what the old one believed about past windows means nothing."""
        if self.smoother is not None:
            self.smoother.reset()

    def _smoothed(
        self, scene: str, scores: dict[str, float]
    ) -> tuple[str, float, dict[str, float]]:
        """The window's judgement through the forward filter: (scene or UNKNOWN, confidence in
        percent, {scene: probability}) of the belief after this window."""
        assert self.smoother is not None
        with self._lock:
            belief = self.smoother.update(scores if scene != UNKNOWN else {UNKNOWN: 1.0})
        best = max(belief, key=lambda s: belief[s])
        return best, 100.0 * belief[best], {s: p for s, p in belief.items() if s != UNKNOWN}

    def _look(self) -> None:
        t = self.clock()
        with self._lock:
            events = self.fusion.tick(t)
            wants = self.camera is not None and self.fusion.wants_picture(t)
        self._handle(events)
        self._check_arm(t)
        if not wants:
            return
        with self._camera_lock:
            frame = self._grab(t)
        if frame is not None:
            self._guarded("visual prediction", self._on_picture, frame, t)

    def _grab(self, t: float) -> np.ndarray | None:
        """A frame from the camera, reopening it if it failed a while ago; None if none."""
        assert self.camera is not None
        if not self._camera_ok:
            if t < self._camera_retry_at:
                return None
            self._open_camera()
            if not self._camera_ok:
                return None
        try:
            frame = self.camera.read()
        except ServantError as error:
            self._camera_fault(error)
            return None
        self._report("camera", True, f"{self.camera.name}: ready")
        return frame

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
            self._scores["visual"] = scores
            events = self.fusion.on_visual(scene if known else None, confidence, t)
        unit = visual.confidence_unit
        self._emit(VisualPrediction(t, scene if known else None, confidence, scores, unit))
        # The decision (and the arm's move) first; the palette is only for show.
        self._handle(events)
        matched = visual.matched_palette(X)[0] if hasattr(visual, "matched_palette") else None
        self._emit(Palette(t, *dominant_colours(frame), scene if known else None, matched))
        if not known:
            self._ask_label("image", _Kept("image", frame), scores, t)

    def _handle(self, events: list[Any]) -> None:
        for event in events:
            if isinstance(event, Decision) and event.scene is not None:
                with self._lock:
                    unit = decision_unit(self.acoustic, self.visual)
                event = dataclasses.replace(event, confidence_unit=unit)
            self._emit(event)
            if isinstance(event, Decision) and event.scene is not None:
                self._act(event.scene)

    # --- actions and the arm ------------------------------------------------------------------

    def set_action_learner(self, pose_for: PoseFor | None) -> None:
        """Attach what turns a detected scene into a pose: a callable
        (scene, scores, confidence) → {joint: degrees} or None, e.g. `ActionLearner.pose_for`.
        `scores` are the latest per-sense scene scores; `confidence` (percent) is the smaller of
        the two senses' probabilities for the scene. None detaches it."""
        self._pose_for = pose_for

    def set_arm(self, link: Any, why_none: str = "servo: no arm attached") -> None:
        """Attach a servo link (`servant_core.servo.link`: `.arm()`, `.disarm()`, `.armed`,
        `.move_to(pose)`, `.status()`), or None to detach it (`why_none` says why). The link
        enforces limits and rate. A link attached here is not closed by the engine."""
        self._link = link
        if link is None:
            self._report("servo", False, why_none)
        else:
            self._report("servo", True, f"servo: {getattr(link, 'port', None) or 'link'} attached")
        self._emit_arm_state()

    def connect_arm(self, port: str | None, protocol: str, joints: Sequence[Any]) -> None:
        """Open the arm the settings name (disarmed) and attach it, closing the one this method
        attached before; the engine closes it when it stops. A missing port or a controller that
        does not answer is reported as the servo's status, never raised: the senses go on.
        Asking again for the same port, protocol and joints keeps the link as it is."""
        from servant_core.servo.link import ServoLink

        spec = (port, protocol, tuple(joints))
        if spec == self._arm_spec and self._link is not None:
            return
        self._close_arm()
        if not port:
            self.set_arm(None, "servo: no serial port set; choose the arm's port in Settings (s)")
            return
        try:
            link = ServoLink.open(port, protocol, list(joints))
        except ServantError as error:
            self.set_arm(None, str(error))
            return
        self._arm_spec = spec
        self.set_arm(link)

    def _close_arm(self) -> None:
        """Disarm and close the link `connect_arm` opened, if any."""
        if self._arm_spec is None:
            return
        link, self._link, self._arm_spec = self._link, None, None
        if link is not None:
            try:
                link.disarm()
            finally:
                link.close()

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
                policy: Any = type(self.fusion)
                self.fusion = policy(config)
            self.confidence_threshold = float(settings.confidence_threshold)
            state = self.fusion.state(self.clock())
        self._emit(state)
        if self._link is None or self._arm_spec is not None:  # not an arm given to `set_arm`
            self.connect_arm(settings.serial_port, settings.protocol, settings.joints)

    def arm(self) -> None:
        """Allow the arm to move (delegates to the link); ServantError if no arm is attached."""
        self._require_link().arm()
        self._emit_arm_state()

    def disarm(self) -> None:
        """Forbid the arm to move; does nothing when no arm is attached (safe to call always)."""
        if self._link is not None:
            self._link.disarm()
            self._emit_arm_state()

    def _require_link(self) -> Any:
        if self._link is None:
            raise ServantError("servo: no arm attached; connect one with `servant servo` first")
        return self._link

    def _emit_arm_state(self) -> None:
        state = self._link.status() if self._link is not None else None
        if isinstance(state, ArmState):
            # the link stamps its own clock; events carry the engine's
            self._emit(dataclasses.replace(state, t=self.clock()))

    def _act(self, scene: str) -> None:
        link, pose_for, pool = self._link, self._pose_for, self._arm_pool
        if link is None or not link.armed:
            return
        if pose_for is None:
            self._emit(Notice(self.clock(), NO_POSE))
            return
        scores = self.latest_scores()
        confidence = 100.0 * min(scores[sense].get(scene, 0.0) for sense in ("acoustic", "visual"))
        threshold = self.confidence_threshold
        if threshold is not None and confidence < threshold:
            self._emit(
                Notice(
                    self.clock(),
                    f"arm stays put: {scene} is only {confidence:.0f} % sure, under the "
                    f"{threshold:g} % threshold (Settings)",
                )
            )
            return
        try:
            pose = pose_for(scene, scores, confidence)
        except ServantError as error:
            self._error(str(error))
            return
        if pose is None:
            return
        if pool is None:  # run_until: no thread pool, send on this thread
            self._move(link, dict(pose))
        else:
            pool.submit(self._move, link, dict(pose))

    def _check_arm(self, t: float) -> None:
        """Every `reopen_seconds`, ask an armed arm where it is (on the arm's thread): a
        controller unplugged while the arm stands still would otherwise stay "ARMED" on screen
        until the next move. A lost link disarms itself; its reason becomes the servo's status."""
        link, pool = self._link, self._arm_pool
        if link is None or pool is None or not link.armed or t < self._arm_checked_at:
            return
        self._arm_checked_at = t + self.reopen_seconds
        pool.submit(self._ask_arm, link)

    def _ask_arm(self, link: Any) -> None:
        try:
            link.read_positions()
        except ServantError as error:
            self._report("servo", False, str(error))
            self._emit_arm_state()

    def _move(self, link: Any, pose: dict[str, float]) -> None:
        # On its own thread: a rate-limited move takes seconds and must not hold up the senses.
        try:
            if link.armed:
                link.move_to(pose)
        except ServantError as error:
            self._report("servo", False, str(error))
        except Exception as exc:
            self._report("servo", False, f"servo: move failed ({type(exc).__name__}: {exc})")
        self._emit_arm_state()

    # --- what the front end asks for ----------------------------------------------------------

    @property
    def audio_rate(self) -> int:
        """The rate of the audio source (what `record_window` returns); 0 without audio."""
        return self.audio.rate if self.audio is not None and self._audio_ok else 0

    def record_window(
        self, seconds: float = DEFAULT_WINDOW_SECONDS, timeout: float | None = None
    ) -> np.ndarray:
        """Record the next `seconds` of audio from now (blocks until they have arrived).

        Returns mono float32 at `audio_rate`. Raises ServantError without a working audio source
        or if the audio does not arrive within `timeout` (default: twice `seconds` plus 2 s).
        """
        if not self.running:
            raise ServantError("engine: not running; start it before recording")
        ring = self._ring
        if ring is None or not self._audio_ok or self.audio is None:
            raise ServantError("microphone: no sound to record; check the microphone (see status)")
        count = int(round(seconds * self.audio.rate))
        if count > ring.capacity:
            raise ServantError(f"engine: cannot record more than {RING_SECONDS:g} s at once")
        end = ring.total + count
        if not ring.wait_for(end, timeout if timeout is not None else 2 * seconds + 2):
            raise ServantError(f"{self.audio.name}: the sound stopped while recording; try again")
        return ring.read(end - count, end)

    def take_picture(self) -> np.ndarray:
        """A picture from the camera now (BGR uint8); ServantError if there is none."""
        if self.camera is None:
            raise ServantError("camera: none in use; start with a camera to take pictures")
        with self._camera_lock:
            frame = self._grab(self.clock())
        if frame is None:
            message = self._status.get("camera")
            raise ServantError(message.message if message else "camera: no picture")
        return frame

    def latest_scores(self) -> dict[str, dict[str, float]]:
        """The last per-scene scores: {"acoustic": {scene: p}, "visual": {scene: p}}."""
        with self._lock:
            return {sense: dict(scores) for sense, scores in self._scores.items()}

    def retrain(
        self,
        library: SceneLibrary | str | Path,
        on_progress: Callable[[int, int], None] | None = None,
    ) -> None:
        """Refit copies of both recognisers on a scene library, then swap them in (the senses keep
        running on the old ones meanwhile). A sense without a recogniser gets a new one of its
        `fresh_methods` method. Unreadable files are reported and skipped. A sense that cannot
        be trained (e.g. pictures of one scene only) is reported and keeps its recogniser while
        the other is retrained; if neither can be, the first reason is raised. `on_progress(done,
        total)` is called after each file read, recordings then pictures, on this thread."""
        if not isinstance(library, SceneLibrary):
            library = SceneLibrary.scan(library)
        with self._update_lock:
            with self._lock:
                acoustic, visual = self.acoustic, self.visual
            new_acoustic = new_visual = None
            failures: list[ServantError] = []
            total, heard = len(library.recordings) + len(library.pictures), len(library.recordings)
            sound_done = progress_part(on_progress, 0, total)
            visual_done = progress_part(on_progress, heard, total)
            try:
                new_acoustic = self._refit_acoustic(library, acoustic, sound_done)
            except ServantError as error:
                failures.append(ServantError(f"retrain (sound): {error}"))
            try:
                new_visual = self._refit_visual(library, visual, visual_done)
            except ServantError as error:
                failures.append(ServantError(f"retrain (pictures): {error}"))
            if new_acoustic is None and new_visual is None:
                if failures:
                    raise failures[0]
                return
            for failure in failures:
                self._error(str(failure))
            with self._lock:
                if new_acoustic is not None:
                    self.acoustic = new_acoustic
                    self._forget_windows()
                self.visual = new_visual or self.visual
                self.retrain_needed = False
            self._save_models()

    def _refit_acoustic(
        self, library: SceneLibrary, acoustic: Recogniser | None, on_progress: Any = None
    ) -> Any:
        """A copy of `acoustic` (or a fresh one) fitted on the library's windows; None if none."""
        if not library.recordings:
            return None
        model = self._copy_or_fresh(acoustic, "audio")
        windows = featurize_recordings(
            library.recordings,
            model.featurize,
            rate=getattr(model, "rate", DEFAULT_RATE),
            seconds=self.window_seconds,
            on_error=lambda e: self._error(str(e)),
            on_progress=on_progress,
        )
        return model.fit(windows.features, list(windows.scenes))

    def _refit_visual(
        self, library: SceneLibrary, visual: Recogniser | None, on_progress: Any = None
    ) -> Any:
        """A copy of `visual` (or a fresh one) fitted on the library's pictures; None if none."""
        if not library.pictures:
            return None
        model = self._copy_or_fresh(visual, "image")
        images, kept = read_pictures(
            library.pictures, on_error=lambda e: self._error(str(e)), on_progress=on_progress
        )
        if not images:
            return None
        return model.fit(model.featurize(images), [p.scene for p in kept])

    def _copy_or_fresh(self, recogniser: Recogniser | None, sense: str) -> Any:
        if recogniser is not None:
            return copy.deepcopy(recogniser)
        return make_recogniser(sense, self.fresh_methods[sense])

    def _ask_label(self, sense: str, kept: _Kept, scores: dict[str, float], t: float) -> None:
        with self._lock:
            self._unknown_count += 1
            window_id = f"{sense}-{self._unknown_count}"
            self._unknown[window_id] = kept
            while len(self._unknown) > UNKNOWN_KEPT:
                self._unknown.popitem(last=False)
        nearest = max(scores, key=lambda s: scores[s]) if scores else None
        self._emit(UnknownScene(t, sense, nearest, window_id))

    def label_unknown(self, window_id: str, scene: str) -> Path:
        """Give the scene the user named to an unknown window or picture (from `UnknownScene`).

        It is written into the library (`library_root/<scene>/`, atomically), then folded into a
        copy of the recogniser that replaces it, if it has `fold_in(X, scenes)`; otherwise
        `retrain_needed` becomes True. With a `model_path`, the updated model is saved there.
        Returns the file written.
        """
        scene = scene.strip()
        if not re.fullmatch(r"[^/\\.][^/\\]*", scene):
            raise ServantError(f"scene name {scene!r}: use a plain folder name, e.g. 'kitchen'")
        with self._lock:
            kept = self._unknown.pop(window_id, None)
        if kept is None:
            raise ServantError(
                f"{window_id}: no such unknown window (only the last {UNKNOWN_KEPT} are kept)"
            )
        root = self.library_root or data_dir() / "library"
        stamp = time.strftime("%Y%m%d-%H%M%S")
        if kept.sense == "audio":
            path = write_wav(root / scene / f"heard-{stamp}-{window_id}.wav", kept.data, kept.rate)
        else:
            ok, png = cv2.imencode(".png", kept.data)
            if not ok:
                raise ServantError(f"{window_id}: the picture could not be encoded as PNG")
            path = atomic_write_bytes(root / scene / f"seen-{stamp}-{window_id}.png", png.tobytes())
        with self._update_lock:
            with self._lock:
                recogniser = self.acoustic if kept.sense == "audio" else self.visual
                if recogniser is None or not hasattr(recogniser, "fold_in"):
                    self.retrain_needed = True
                    return path
            if kept.sense == "audio":
                samples = resample(kept.data, kept.rate, getattr(recogniser, "rate", kept.rate))
                X = recogniser.featurize(samples[None, :])
            else:
                X = recogniser.featurize([kept.data])
            # The sense thread may be predicting with this model right now: fold into a copy and
            # swap it in, as `retrain` does, so that no prediction sees half of an update.
            model = copy.deepcopy(recogniser)
            model.fold_in(X, [scene])
            with self._lock:
                if kept.sense == "audio":
                    self.acoustic = model
                    self._forget_windows()
                else:
                    self.visual = model
            self._save_models()
        return path

    def _save_models(self) -> None:
        """Write the current recognisers to `model_path` (called under `_update_lock`). A failed
        write is reported; the file keeps its previous content (atomic replace)."""
        if self.model_path is None:
            return
        with self._lock:
            models = {
                role: model
                for role, model in (("acoustic", self.acoustic), ("visual", self.visual))
                if model is not None
            }
        try:
            save_model(self.model_path, models)
        except (OSError, ServantError) as error:
            self._error(
                f"{self.model_path}: the updated model could not be saved ({error}); it is used "
                "until the program ends, and the file keeps the previous model"
            )


def progress_part(
    on_progress: Callable[[int, int], None] | None, offset: int, total: int
) -> Callable[[int, int], None] | None:
    """A part of a job reports `(done, its own total)`; the job's `on_progress` hears
    `(offset + done, total)`, so one bar runs over every part without going back."""
    if on_progress is None:
        return None
    report = on_progress
    return lambda done, _part_total: report(offset + done, total)


def decision_unit(*recognisers: Recogniser | None) -> str | None:
    """The unit of an average of these recognisers' confidences (a decision's): theirs when they
    all share one, as percentages do; else None (the paper's eq. 1 and eq. 2 share none)."""
    units = {getattr(r, "confidence_unit", None) for r in recognisers}
    return units.pop() if len(units) == 1 else None


def _predict(recogniser: Recogniser, X: np.ndarray) -> tuple[str, float, dict[str, float]]:
    """(scene or UNKNOWN, confidence, {scene: probability}) for a single featurized row."""
    scene = str(recogniser.predict(X)[0])
    confidence = float(recogniser.confidence(X)[0])
    probabilities = recogniser.predict_proba(X)[0]
    return (
        scene,
        confidence,
        {s: float(p) for s, p in zip(recogniser.scenes_, probabilities, strict=True)},
    )


# --- factories for front ends ---------------------------------------------------------------


def build_demo_engine(
    seed: int = 0,
    clock: Callable[[], float] | None = None,
    realtime: bool = True,
    fusion: FusionPolicy | None = None,
    library_root: str | Path | None = None,
    arm: bool = True,
    paper: bool = False,
    on_progress: Callable[[int, int], None] | None = None,
) -> Engine:
    """The built-in demo: recognisers trained on freshly synthesised scenes (a couple of seconds),
    then the synthesised walk (see `servant_core.demo.scenes`). By default Servant at its best:
    the fresh methods (`FRESH_METHODS`) in percentages, smoothed, with the parallel policy;
    `paper` gives the paper's recognisers (eqs. 1 and 2) and its sequential 30 s / 20 s policy.
    With `arm`, an emulated arm (`servant_core.demo.arm`), disarmed, that the engine closes when
    it stops. With `library_root`, the demo's training scenes are written there as a scene
    library (the demo's own throw-away space: see `servant_core.demo.space`), for the library
    screen and retrains. `on_progress(done, total)` follows the training (the slow part).

    `realtime=False` runs the walk as fast as possible on a `ManualClock` (pass your own to read
    it), so events — times included — are the same on every run: use `engine.run_until(t)` for a
    thread-free deterministic run, or `start()` to stream them. With `realtime=True` the walk
    plays at real speed on `clock` (default: monotonic time).
    """
    from servant_core.demo.scenes import (
        DemoCamera,
        demo_audio,
        train_demo_recognisers,
        write_demo_library,
    )

    if not realtime:
        clock = clock if isinstance(clock, ManualClock) else ManualClock()
    clock = clock or MonotonicClock()
    acoustic, visual = train_demo_recognisers(seed, paper=paper, on_progress=on_progress)
    if library_root is not None:
        write_demo_library(library_root, seed)
    audio = demo_audio(seed, realtime=realtime, clock=clock if not realtime else None)
    if fusion is None:
        fusion = SequentialFusion() if paper else POLICIES["parallel"]()
    engine = Engine(
        audio=audio,
        camera=DemoCamera(clock, seed),
        acoustic=acoustic,
        visual=visual,
        fusion=fusion,
        clock=clock,
        library_root=library_root,
        smoother=None if paper else steady(),
    )
    if arm:
        from servant_core.demo.arm import demo_learner, start_demo_arm

        emulator, link = start_demo_arm()
        engine.add_cleanup(emulator.stop)
        engine.add_cleanup(link.close)  # runs first: the link closes before its emulator
        engine.set_arm(link)
        engine.set_action_learner(pose_for_taught(demo_learner()))
    return engine


def steady() -> SceneSmoother:
    """The smoothing of live decisions: one odd window does not flip the scene, two do."""
    return SceneSmoother(stay=STEADY_STAY, floor=STEADY_FLOOR)


def fusion_config(settings: Any) -> FusionConfig:
    """The fusion windows of the user's settings (`servant_core.settings.Settings`)."""
    return FusionConfig(
        acoustic_window_s=settings.acoustic_window_s,
        confirm_window_s=settings.confirm_window_s,
        pictures_needed=settings.pictures_needed,
        picture_interval_s=settings.picture_interval_s,
    )


def pose_for_taught(learner: Any) -> PoseFor:
    """The engine's action hook for an `ActionLearner`: the pose taught for the decided scene.

    The learner is asked for the decided scene as a certainty (one-hot scores), not for the
    senses' raw scores: those are never one-hot, and a wearer who taught "cup at chest height"
    for the café wants that pose, not a blend with the street's. The engine has applied the
    confidence threshold of the settings (which the user may change while it runs) before it
    asks, so the learner's own, fixed when it was trained, is not applied a second time."""

    def pose_for(scene: str, scores: dict[str, dict[str, float]], confidence: float) -> Pose:
        return learner.pose_for(scene, None, 100.0)

    return pose_for


@dataclass(frozen=True)
class LiveSettings:
    """What `build_live_engine` needs; every field has a sensible default.

    `model`: a model file from `servant train` (None: no recognisers, senses only).
    `model_path`: where retrains and fold-ins are saved (None: back to `model`).
    `microphone`: device index or name (None: the default input); `rate`: None for its default.
    `camera`: index, video file or image-sequence pattern (None: no camera).
    `user`: the user's settings (`servant_core.settings.Settings`: fusion windows, confidence
    threshold, the arm's port, protocol and joints); None: the defaults, and no arm.
    `policy`: the fusion policy's name (`servant_core.fusion.POLICIES`).
    `learner`: the action learner file teach mode trains (None: `default_learner_path()`, if
    there is one yet).
    """

    model: str | Path | None = None
    model_path: str | Path | None = None
    microphone: int | str | None = None
    rate: int | None = None
    use_microphone: bool = True
    camera: int | str | None = 0
    library_root: str | Path | None = None
    user: Any = None
    policy: str = "parallel"
    learner: str | Path | None = None


def build_live_engine(
    settings: LiveSettings | None = None, fusion: FusionPolicy | None = None
) -> Engine:
    """An engine on the live devices and the arm of the user's settings, with the poses taught
    in teach mode. A missing microphone, camera or arm, or no poses taught yet, is reported when
    the engine starts (`DeviceStatus(ok=False)`, `Notice`), never raised: the engine runs on
    what there is. A model file that cannot be read is raised (ServantError)."""
    from servant_core.actions.learner import ActionLearner, default_learner_path
    from servant_core.capture.camera import Camera
    from servant_core.capture.microphone import Microphone
    from servant_core.modelfile import load_model
    from servant_core.settings import Settings

    settings = settings or LiveSettings()
    user = settings.user or Settings()
    models = load_model(settings.model) if settings.model else {}
    engine = Engine(
        audio=Microphone(settings.microphone, settings.rate) if settings.use_microphone else None,
        camera=Camera(settings.camera) if settings.camera is not None else None,
        acoustic=models.get("acoustic"),
        visual=models.get("visual"),
        fusion=fusion or POLICIES[settings.policy](fusion_config(user)),
        library_root=settings.library_root,
        model_path=settings.model_path or settings.model,
        confidence_threshold=user.confidence_threshold,
        smoother=steady(),
    )
    engine.connect_arm(user.serial_port, user.protocol, user.joints)
    learner_file = Path(settings.learner or default_learner_path())
    if settings.learner is not None or learner_file.is_file():
        try:
            engine.set_action_learner(pose_for_taught(ActionLearner.load(learner_file)))
        except ServantError as error:
            engine.note(f"{error}; the arm stays put until a pose is taught again")
    return engine
