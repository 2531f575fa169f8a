"""`servant run` (live devices) and `servant demo` (the synthesised walk), headless.

They print the paper's terminal lines ("CoffeeScene detected") with their confidences, and what
was heard and seen, as it happens; a decision, the arm and an unknown place are said when they
change, not at every window they hold. `--json` prints one JSON object per event instead. They
stop on Ctrl-C or after `--duration` seconds of engine time. Without `--headless` the `servant`
console script opens the terminal application instead; if it does not, they run headless.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING, Any

from servant_core.cli import reader_gone, terminal_text, write_line
from servant_core.cli.options import bounded_int, finite_float, sample_rate
from servant_core.errors import ServantError
from servant_core.senses import SAMPLE_SENSES

if TYPE_CHECKING:  # the engine and its libraries load when a command runs, not for its --help
    from servant_core.engine import Engine, LiveSettings
    from servant_core.events import Event

RUN_DESCRIPTION = """Recognise the scene from the live microphone and camera and, once armed, move
the arm to the pose taught for it. Devices, the arm's port and joints, the fusion windows and the
confidence threshold come from the settings file (the terminal app's Settings, key s); the options
below override them for this run. Without --headless the terminal app opens."""

DEMO_DESCRIPTION = """The built-in demo: a walk through a coffee shop, a gym and a street, all
synthesised, with an emulated arm; no microphone, camera or arm needed. What you teach or record
in the demo goes to a temporary folder, deleted when it ends."""


def register(subparsers: Any) -> None:
    """Add `run` (its devices, the arm, the fusion policy) and `demo` (its seed and policy), both
    with `--headless`, `--duration` and `--json`."""
    run = subparsers.add_parser(
        "run",
        description=RUN_DESCRIPTION,
    )
    run.add_argument(
        "--model",
        help="model file from `servant train`; what you teach is saved back to it (default: the "
        "model teach mode saved, if any)",
    )
    _device_options(run)
    _arm_options(run)
    _run_policy_option(run)
    run.add_argument("--list-devices", action="store_true", help="list input devices and exit")
    _common(run)
    run.set_defaults(handler=run_live)
    _register_demo(subparsers.add_parser("demo", description=DEMO_DESCRIPTION))


def _device_options(run: argparse.ArgumentParser) -> None:
    """`run`'s senses: the microphone, the camera and a source per sample sense."""
    run.add_argument(
        "--mic",
        help="input device index or name (default: Settings, else the "
        "system's default input; see --list-devices)",
    )
    run.add_argument(
        "--rate", type=sample_rate, help="sample rate in Hz (default: the device's own)"
    )
    run.add_argument("--no-mic", action="store_true", help="do not listen")
    run.add_argument(
        "--camera", help="camera index, video file or image pattern (default: Settings, else 0)"
    )
    run.add_argument("--no-camera", action="store_true", help="do not look")
    for sense in SAMPLE_SENSES.values():  # --imu, --ambient: one option per sample sense
        run.add_argument(
            f"--{sense.stream}",
            metavar="PORT|LOG|FOLDER",
            help=f"{sense.label}: the sensor board's serial port (one board may carry every "
            f"sense), a log (*{sense.suffixes[0]}, as phone sensor-logger apps export) or a "
            "folder of them (docs/sensors.md)",
        )


def _arm_options(run: argparse.ArgumentParser) -> None:
    """`run`'s arm: its port, its controller, and whether it moves from the start."""
    from servant_core.settings import PROTOCOLS

    run.add_argument(
        "--port", help="the arm's serial port (default: Settings; see `servant servo list-ports`)"
    )
    run.add_argument(
        "--protocol", choices=PROTOCOLS, help="the arm's controller (default: Settings)"
    )
    run.add_argument(
        "--arm",
        action="store_true",
        help="arm the arm at once, so that detected scenes move it (in the app: key a); "
        "without it the arm never moves",
    )


def _run_policy_option(run: argparse.ArgumentParser) -> None:
    """`run --policy`: how the senses' opinions become a decision."""
    from servant_core.choices import DEFAULT_POLICY, POLICY_NAMES

    run.add_argument(
        "--policy",
        choices=sorted(POLICY_NAMES),
        default=DEFAULT_POLICY,
        help="fusion: `sequential` is the paper's 30 s / 20 s rule; `learned` is a small neural "
        "net over every sense (trained with the model; without one it acts as `parallel`)",
    )


def _register_demo(demo: argparse.ArgumentParser) -> None:
    """`demo`'s options: the seed of its scenes, the paper's methods, the policy, `--fast`."""
    from servant_core.choices import POLICY_NAMES

    demo.add_argument(
        "--seed", type=bounded_int(0, 2**31 - 1), default=0, help="seed of the synthesised scenes"
    )
    demo.add_argument(
        "--paper",
        action="store_true",
        help="the paper's own recognisers (eqs. 1 and 2) and its sequential 30 s / 20 s fusion, "
        "instead of the methods beyond it",
    )
    demo.add_argument(
        "--policy",
        choices=sorted(POLICY_NAMES),
        help="fusion (default: parallel; sequential with --paper); `learned` teaches its net on "
        "the demo's scenes first and shows which senses each decision leaned on",
    )
    demo.add_argument(
        "--fast", action="store_true", help="as fast as possible on a simulated clock (headless)"
    )
    _common(demo)
    demo.set_defaults(handler=run_demo)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--headless", action="store_true", help="print lines, no terminal UI")
    parser.add_argument(
        "--duration",
        type=finite_float(0.0, 7 * 24 * 3600.0),
        help="stop after this many seconds (default: run until Ctrl-C)",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object per event")


def run_live(args: argparse.Namespace) -> int:
    if args.list_devices:
        from servant_core.capture.microphone import list_input_devices

        for device in list_input_devices():
            mark = "*" if device.is_default else " "
            rate = f"{device.channels} ch, {device.default_rate} Hz"
            print(f"{mark} {device.index:3d}  {device.name}  ({rate})")
        return 0
    return _run(build_run_engine(args), args)


def build_run_engine(args: argparse.Namespace | None = None) -> Engine:
    """The live engine for `servant run ARGS` (None: `servant` alone), armed if `--arm` was given;
    ServantError when the settings or the model cannot be read, or `--arm` finds no arm."""
    from servant_core.engine import build_live_engine

    engine = build_live_engine(live_settings(args))
    if args is not None and args.arm:
        try:
            engine.arm()
        except ServantError as error:
            engine.stop()
            raise ServantError(f"{error} (--arm needs an arm that answers)") from error
    return engine


def live_settings(args: argparse.Namespace | None = None) -> LiveSettings:
    """The user's settings file with `servant run`'s options over it; None (`servant` alone):
    the settings file alone.

    Without `--model`, the model that teach mode and the library screen last saved is loaded
    (`default_model_file()`, if there is one yet) and retrains and fold-ins are saved back to it.
    """
    from servant_core.engine import LiveSettings
    from servant_core.settings import load_settings
    from servant_core.storage import default_model_file

    user = load_settings()
    default = default_model_file()
    taught = default if default.is_file() else None
    camera = user.camera if user.camera is not None else 0
    port = user.sensor_port
    board = {s.stream: port for s in SAMPLE_SENSES.values() if s.stream and port}
    if args is None:
        return LiveSettings(
            model=taught,
            model_path=default,
            microphone=user.audio_device,
            camera=camera,
            user=user,
            sensors=board,
        )
    changes = {"serial_port": args.port, "protocol": args.protocol}
    user = dataclasses.replace(user, **{k: v for k, v in changes.items() if v is not None})
    return LiveSettings(
        model=args.model or taught,
        model_path=args.model or default,
        microphone=args.mic if args.mic is not None else user.audio_device,
        rate=args.rate,
        use_microphone=not args.no_mic,
        camera=None if args.no_camera else (args.camera if args.camera is not None else camera),
        user=user,
        policy=args.policy,
        sensors=_sensors(args, board),
    )


def _sensors(args: argparse.Namespace, board: dict[str, str]) -> dict[str, str]:
    """{stream: port or log} from `--imu`, `--ambient`…; without any, the settings' board."""
    given = {
        s.stream: getattr(args, s.stream)
        for s in SAMPLE_SENSES.values()
        if s.stream and getattr(args, s.stream, None) is not None
    }
    return given or board


def run_demo(args: argparse.Namespace) -> int:
    from servant_core.demo.space import throwaway_space
    from servant_core.engine import build_demo_engine

    with throwaway_space() as space:
        engine = build_demo_engine(
            args.seed,
            realtime=not args.fast,
            paper=args.paper,
            library_root=space / "library",
            write_library=False,  # printed lines have no library screen and no retrain
            policy=args.policy,
        )
        if args.fast:
            show = _Printer(args.json, engine.library_root)
            engine.subscribe(show)
            end = args.duration if args.duration is not None else 95.0
            while not show.gone.is_set():  # a second at a time, to stop once the reader has gone
                before = engine.clock()
                engine.run_until(min(end, before + 1.0))
                if engine.clock() >= end or engine.clock() == before:  # the end, or no more sound
                    break
            engine.stop()
            return show.status()
        return _run(engine, args)


def _run(engine: Engine, args: argparse.Namespace) -> int:
    if not args.headless:
        print("servant: the terminal UI is not attached here; running headless", file=sys.stderr)
    show = _Printer(args.json, engine.library_root)
    engine.subscribe(show)
    engine.start()
    try:
        while engine.running and (args.duration is None or engine.clock() < args.duration):
            if show.gone.wait(0.05):
                break
    except KeyboardInterrupt:
        pass
    finally:
        engine.stop()
    return show.status()


class _Printer:
    """Prints each event's line (or JSON); `gone` is set once the output cannot be written (its
    reader has gone, `| head -n 5`, or its disk is full), which ends the run (the arm disarmed
    as at any end), not a traceback for every event after."""

    def __init__(self, as_json: bool, library: Path | None = None) -> None:
        self.as_json = as_json
        self.lines = _Lines(library)
        self.gone = threading.Event()
        self.failed = False  # gone because the output failed, not because its reader left

    def status(self) -> int:
        """The command's exit status once the run has ended."""
        if not self.gone.is_set():
            return 0
        return 2 if self.failed else reader_gone()

    def __call__(self, event: Event) -> None:
        text = _event_json(event) if self.as_json else self.lines(event)
        if text is None or self.gone.is_set():
            return
        try:
            write_line(terminal_text(text))
        except BrokenPipeError:
            reader_gone()
            self.gone.set()
        except ServantError as error:  # a full disk where the output goes: said once, then end
            print(f"servant: error: {error}", file=sys.stderr)
            self.failed = True
            self.gone.set()


def _printer(as_json: bool) -> Any:
    return _Printer(as_json)


class _Lines:
    """The lines of a headless run: `_event_line`, for the events `log_news.LogNews` says are
    news (a decision or the arm's state when it changes, not at every window it holds; a place
    decided said to be left when the sound stops naming one), and an unknown place when it
    begins. The first unknown place says what it is and how to teach it; a run at one place for
    an hour is a handful of lines, not thousands."""

    def __init__(self, library: Path | None = None) -> None:
        from servant_core.log_news import LogNews

        self.library = library
        self.news = LogNews()
        self._unknown: set[str] = set()  # the senses whose unknown place was said and holds
        self._taught_how = False
        self._lock = threading.Lock()  # events come from the senses' and the arm's threads

    def __call__(self, event: Event) -> str | None:
        from servant_core.event_text import left_text
        from servant_core.events import UnknownScene
        from servant_core.fusion.sequential import scene_line

        with self._lock:
            news = self.news(event)
            line = _event_line(event)
            if line is None or not news.said or not self._new(event):
                return None
            if isinstance(event, UnknownScene):
                self._unknown.add(event.sense)
                if not self._taught_how:
                    self._taught_how = True
                    return f"[{event.t:7.2f}] {self._how_to_teach(event)}"
        if news.left is not None:
            left = f"[{event.t:7.2f}] {scene_line(None)}  ({left_text(news.left, news.silent)})"
            return f"{line}\n{left}"
        return line

    def _new(self, event: Event) -> bool:
        """Whether an unknown place's `event` says something the lines have not said yet (under
        `_lock`): each sense's unknown place once, until that sense names a place again."""
        from servant_core.events import (
            AcousticPrediction,
            SensePrediction,
            UnknownScene,
            VisualPrediction,
        )

        if isinstance(event, UnknownScene):
            return event.sense not in self._unknown
        if isinstance(event, (AcousticPrediction, VisualPrediction, SensePrediction)):
            if event.scene is not None:  # a known place: the next unknown one is news again
                self._unknown.discard(_sense_of(event))
        return True

    def _how_to_teach(self, event: Any) -> str:
        """The first unknown place's line: what its id is, and how to teach the place."""
        from servant_core.event_text import place
        from servant_core.storage import data_dir

        # where the engine writes the places it is told (`Engine.label_unknown`)
        library = self.library or data_dir() / "library"
        nearest = f", nearest: {place(event.nearest_scene)}" if event.nearest_scene else ""
        return (
            f"{event.window_id}: a place Servant was not taught ({event.sense}{nearest}); to teach "
            f"it, run `servant` there (teach mode, key t), or put recordings and pictures of it in "
            f"{library}/<name>/ and run `servant train {library} --force`"
        )


def _sense_of(prediction: Any) -> str:
    """The sense a prediction is of, by the name `UnknownScene.sense` gives it."""
    from servant_core.events import AcousticPrediction, VisualPrediction

    if isinstance(prediction, AcousticPrediction):
        return "audio"
    return "image" if isinstance(prediction, VisualPrediction) else str(prediction.sense)


def _event_line(event: Event) -> str | None:
    """The line a person reads for an event, or None for events too frequent to print."""
    from servant_core.event_text import SILENCE, arm_text, confidence_text, place
    from servant_core.events import (
        AcousticPrediction,
        ArmState,
        Decision,
        DeviceStatus,
        ErrorEvent,
        Notice,
        SensePrediction,
        UnknownScene,
        VisualPrediction,
    )

    at = f"[{event.t:7.2f}]"
    if isinstance(event, (Decision, AcousticPrediction, VisualPrediction)):
        confidence = confidence_text(event.confidence, event.confidence_unit)
        if isinstance(event, Decision):
            leaned = f"  leaned on {', '.join(event.leaned_on)}" if event.leaned_on else ""
            if event.scene is None:  # no scene, no confidence to show
                return f"{at} {event.line}{leaned}"
            return f"{at} {event.line}  confidence {confidence}{leaned}"
        verb, sense = (
            ("heard", "acoustic") if isinstance(event, AcousticPrediction) else ("saw", "visual")
        )
        if event.scene is None:  # a confidence in no scene says nothing
            silent = isinstance(event, AcousticPrediction) and event.silent
            return f"{at} {verb} {SILENCE if silent else place(None)}"
        return f"{at} {verb} {place(event.scene)}  {sense} confidence {confidence}"
    if isinstance(event, SensePrediction):
        if event.scene is None:
            return f"{at} felt ({event.sense}) {place(None)}"
        confidence = confidence_text(event.confidence, event.confidence_unit)
        return f"{at} felt ({event.sense}) {place(event.scene)}  confidence {confidence}"
    if isinstance(event, UnknownScene):
        nearest = f", nearest: {place(event.nearest_scene)}" if event.nearest_scene else ""
        return f"{at} {event.window_id}: {place(None)} again ({event.sense}{nearest})"
    if isinstance(event, DeviceStatus):
        return f"{at} {event.device} {'ok' if event.ok else 'PROBLEM'}: {event.message}"
    if isinstance(event, ErrorEvent):
        return f"{at} error: {event.message}"
    if isinstance(event, Notice):
        return f"{at} note: {event.message}"
    if isinstance(event, ArmState):
        return f"{at} {arm_text(event)}"
    return None


def _event_json(event: Event) -> str | None:
    if _event_line(event) is None:
        return None
    payload = {"event": type(event).__name__, **dataclasses.asdict(event)}
    return json.dumps(payload, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
