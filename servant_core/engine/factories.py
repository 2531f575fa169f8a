"""Engines for front ends: the built-in demo, and the live devices with the user's settings.

Both return an `Engine` that is not started; a missing device is reported when it starts, never
raised here.
"""

from __future__ import annotations

import dataclasses
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from servant_core.capture.source import ManualClock, MonotonicClock
from servant_core.engine.arm import Pose, PoseFor
from servant_core.engine.core import Engine
from servant_core.engine.fusion_settings import fusion_config
from servant_core.engine.loop import DeviceMakers
from servant_core.errors import ServantError
from servant_core.events import Notice
from servant_core.fusion import (
    DEFAULT_POLICY,
    POLICIES,
    FusionConfig,
    FusionNet,
    FusionPolicy,
    LearnedFusion,
)
from servant_core.fusion.smoothing import STEADY_FLOOR, STEADY_STAY, SceneSmoother
from servant_core.senses import SAMPLE_SENSES, SENSES

if TYPE_CHECKING:
    from servant_core.actions.learner import ActionLearner


def walk_narrator(engine: Engine) -> Callable[[Any], None]:
    """A subscriber that says each stretch of the demo's walk as the engine's time enters it:
    where the wearer is, and why the senses disagree where they do by design (the street heard
    while the camera still looks into the café), so the screen never leaves that unexplained."""
    from servant_core.demo.scenes import segment_at

    told: list[Any] = [segment_at(0.0)]
    engine.note(f"demo walk: {told[0].note}")  # said again when the senses open: at the start

    def narrate(event: Any) -> None:
        t = getattr(event, "t", None)
        if not isinstance(t, float | int) or isinstance(event, Notice):
            return
        segment = segment_at(float(t))
        if segment is not told[0]:
            told[0] = segment
            engine.tell(f"demo walk: {segment.note}")

    return narrate


def build_demo_engine(
    seed: int = 0,
    clock: Callable[[], float] | None = None,
    realtime: bool = True,
    fusion: FusionPolicy | None = None,
    library_root: str | Path | None = None,
    write_library: bool = True,
    arm: bool = True,
    paper: bool = False,
    on_progress: Callable[[int, int], None] | None = None,
    policy: str | None = None,
) -> Engine:
    """The built-in demo: recognisers trained on freshly synthesised scenes (a couple of seconds),
    then the synthesised walk (`servant_core.demo.scenes`). By default the fresh methods, smoothed,
    with the parallel policy; `paper`: the paper's recognisers (eqs. 1 and 2) and its sequential
    policy; `policy` names another ("learned" first teaches its net on the demo's library). `arm`:
    an emulated arm, disarmed. `library_root`: where the training scenes are written (not with
    `write_library=False`; a place labelled still goes there). `on_progress(done, total)` follows
    the training. `realtime=False` runs the walk as fast as possible on a `ManualClock` (pass your
    own to read it), the same events on every run; `realtime=True` at real speed on `clock`."""
    from servant_core.demo.scenes import DemoCamera, demo_audio
    from servant_core.demo.sensors import demo_sensor_sources, train_sensor_recognisers

    clock = _demo_clock(clock, realtime)
    training, acoustic, visual = _train_demo_scenes(seed, paper, on_progress)
    samples, stop_emulator = demo_sensor_sources(
        seed, clock=clock if isinstance(clock, ManualClock) and not realtime else None
    )
    sensing = train_sensor_recognisers(seed)
    if library_root is not None and write_library:
        _write_demo_libraries(library_root, seed, training)
    audio = demo_audio(seed, realtime=realtime, clock=clock if not realtime else None)
    why = None
    if fusion is None:
        name = policy or ("sequential" if paper else DEFAULT_POLICY)
        fusion, why = _demo_policy(name, seed, {"audio": acoustic, "image": visual, **sensing})
    engine = Engine(
        audio=audio,
        camera=DemoCamera(clock, seed),
        acoustic=acoustic,
        visual=visual,
        fusion=fusion,
        clock=clock,
        library_root=library_root,
        smoother=None if paper else steady(),
        samples=samples,
        sample_recognisers=sensing,
    )
    if stop_emulator is not None:
        engine.add_cleanup(stop_emulator)
    engine.subscribe(walk_narrator(engine))
    if why is not None:
        engine.note(f"learned fusion: {why}; the parallel policy decides")
    if arm:
        _attach_demo_arm(engine)
    return engine


def _demo_clock(clock: Callable[[], float] | None, realtime: bool) -> Callable[[], float]:
    """The demo's clock: `clock` when given (a `ManualClock` when not `realtime`), else a fresh
    `ManualClock`, or monotonic time in real time."""
    if not realtime:
        clock = clock if isinstance(clock, ManualClock) else ManualClock()
    return clock or MonotonicClock()


def _train_demo_scenes(
    seed: int, paper: bool, on_progress: Callable[[int, int], None] | None
) -> tuple[Any, Any, Any]:
    """The demo's synthesised training set, and the sound and picture recognisers trained on it
    (`paper`: the paper's); `on_progress(done, total)` follows both, over one total."""
    from servant_core.demo.scenes import TRAINING_STEPS, train_demo_recognisers, training_set

    total = TRAINING_STEPS
    if on_progress is not None:
        on_progress(0, total)  # the modules loaded: the work, and its estimate, begin
    training = training_set(
        seed, on_progress=None if on_progress is None else lambda done, _: on_progress(done, total)
    )
    acoustic, visual = train_demo_recognisers(
        seed, paper=paper, on_progress=on_progress, training=training
    )
    return training, acoustic, visual


def _write_demo_libraries(library_root: str | Path, seed: int, training: Any) -> None:
    """The demo's training scenes and sensor logs, written under `library_root` as a library."""
    from servant_core.demo.motion_synth import write_sensor_library
    from servant_core.demo.scenes import write_demo_library

    write_demo_library(library_root, seed, training)
    write_sensor_library(library_root, seed)


def _demo_policy(
    name: str, seed: int, recognisers: dict[str, Any]
) -> tuple[FusionPolicy, str | None]:
    """The demo's fusion policy named `name`; "learned" with its net taught on the demo's
    library, and why there is none when it could not be taught (None otherwise)."""
    net, why = None, None
    if name == "learned":
        net, why = demo_fusion_net(seed, recognisers)
    return live_policy(name, FusionConfig(), net), why


def _attach_demo_arm(engine: Engine) -> None:
    """An emulated arm, disarmed, with the demo's taught poses; its link and emulator close when
    the engine stops, and Settings shows its port."""
    from servant_core.demo.arm import demo_learner, start_demo_arm
    from servant_core.settings import Settings

    emulator, link = start_demo_arm()
    engine.add_cleanup(emulator.stop)
    engine.add_cleanup(link.close)  # runs first: the link closes before its emulator
    engine.set_arm(link)
    engine.set_action_learner(pose_for_taught(demo_learner()))
    # what Settings shows in the demo: the emulated arm's port, not the empty default
    engine.user_settings = Settings(serial_port=link.port, protocol=link.protocol.name)


def demo_fusion_net(seed: int, recognisers: dict[str, Any]) -> tuple[FusionNet | None, str | None]:
    """The learned fusion's net for the demo's recognisers, taught on its library's held-out
    opinions (written to a temporary folder and removed)."""
    from servant_core.demo.motion_synth import write_sensor_library
    from servant_core.demo.scenes import write_demo_library
    from servant_core.engine.learning import library_fusion_net
    from servant_core.library import SceneLibrary

    with tempfile.TemporaryDirectory(prefix="servant-demo-fusion-") as folder:
        write_demo_library(folder, seed)
        write_sensor_library(folder, seed)
        return library_fusion_net(SceneLibrary.scan(folder), recognisers, 5.0, _raise)


def _raise(error: ServantError) -> None:
    raise error


def steady() -> SceneSmoother:
    """The smoothing of live decisions: one odd window does not flip the scene, two do."""
    return SceneSmoother(stay=STEADY_STAY, floor=STEADY_FLOOR)


def pose_for_taught(learner: ActionLearner) -> PoseFor:
    """The engine's action hook for an `ActionLearner`: the pose taught for the decided scene.

    The learner is asked for the decided scene as a certainty (one-hot scores), not a blend of the
    senses' raw scores, and without its own confidence threshold (the engine has applied the
    settings'). A place it was never taught a pose for has none: None, which the engine says once.
    """

    def pose_for(scene: str, scores: dict[str, dict[str, float]], confidence: float) -> Pose | None:
        if scene not in learner.taught_scenes_:
            return None
        return learner.pose_for(scene, None, 100.0)

    return pose_for


def live_policy(name: str, config: FusionConfig, net: FusionNet | None = None) -> FusionPolicy:
    """The fusion policy named `name` (`POLICIES`); the learned one with `net` (None: its
    fallback, the parallel policy, until a net is taught)."""
    if name == "learned":
        return LearnedFusion(config, net)
    policy: FusionPolicy = POLICIES[name](config)
    return policy


@dataclass(frozen=True)
class LiveSettings:
    """What `build_live_engine` needs; every field has a sensible default, described beside it."""

    # a model file from `servant train` (None: no recognisers, senses only)
    model: str | Path | None = None
    # where retrains and fold-ins are saved (None: back to `model`)
    model_path: str | Path | None = None
    # device index or name (None: the default input); `rate`: None for its default
    microphone: int | str | None = None
    rate: int | None = None
    use_microphone: bool = True
    # index, video file or image-sequence pattern (None: no camera)
    camera: int | str | None = 0
    library_root: str | Path | None = None
    # the user's settings (`servant_core.settings.Settings`: fusion windows, confidence threshold,
    # the arm's port, protocol and joints); None: the defaults, and no arm
    user: Any = None
    # the fusion policy's name (`servant_core.fusion.POLICIES`)
    policy: str = DEFAULT_POLICY
    # the action learner file teach mode trains (None: `default_learner_path()`, if there is one)
    learner: str | Path | None = None
    # {stream: the sensor board's serial port, a log or a folder of logs} for the sample senses
    # (`servant_core.senses`: "imu" for motion, "ambient"); a stream left out is not used
    sensors: Mapping[str, str] = dataclasses.field(default_factory=dict)


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
    from servant_core.capture.sensor_sources import sensor_sources
    from servant_core.modelfile import load_model_and_fusion
    from servant_core.settings import Settings

    settings = settings or LiveSettings()
    user = settings.user or Settings()
    models, net = load_model_and_fusion(settings.model) if settings.model else ({}, None)
    streams = sensor_sources(dict(settings.sensors))
    samples = {s.name: streams[s.stream] for s in SAMPLE_SENSES.values() if s.stream in streams}
    engine = Engine(
        audio=Microphone(settings.microphone, settings.rate) if settings.use_microphone else None,
        camera=Camera(settings.camera) if settings.camera is not None else None,
        acoustic=models.get("acoustic"),
        visual=models.get("visual"),
        fusion=fusion or live_policy(settings.policy, fusion_config(user), net),
        library_root=settings.library_root,
        model_path=settings.model_path or settings.model,
        confidence_threshold=user.confidence_threshold,
        smoother=steady(),
        samples=samples,
        sample_recognisers={s: models[SENSES[s].role] for s in samples if SENSES[s].role in models},
    )
    if isinstance(engine.fusion, LearnedFusion) and engine.fusion.net is None and models:
        engine.note(
            "learned fusion: the model has no net yet, so the parallel policy decides; Retrain "
            "in the library (l, R) or `servant train --learned-fusion` teaches it"
        )
    engine.sensor_port = user.sensor_port
    engine.user_settings = settings.user
    rate = settings.rate
    engine.device_makers = DeviceMakers(
        camera=lambda spec: Camera(spec if spec is not None else 0),
        microphone=lambda device: Microphone(device, rate),
    )
    engine.connect_arm(user.serial_port, user.protocol, user.joints)
    learner_file = Path(settings.learner or default_learner_path())
    if settings.learner is not None or learner_file.is_file():
        try:
            engine.set_action_learner(pose_for_taught(ActionLearner.load(learner_file)))
        except ServantError as error:
            engine.note(f"{error}; the arm stays put until a pose is taught again")
    return engine
