"""`servant run` (live devices) and `servant demo` (the synthesised walk), headless.

They print the paper's terminal lines ("CoffeeScene detected") with their confidences, and what
was heard and seen, as it happens; `--json` prints one JSON object per event instead. They stop
on Ctrl-C or after `--duration` seconds of engine time. Without `--headless` the `servant` console
script opens the terminal application instead (servant_tui intercepts these commands); if it does
not, they run headless.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from typing import Any

from servant_core.engine import Engine, LiveSettings, build_demo_engine, build_live_engine
from servant_core.event_text import confidence_text, place
from servant_core.events import (
    AcousticPrediction,
    ArmState,
    Decision,
    DeviceStatus,
    ErrorEvent,
    Event,
    UnknownScene,
    VisualPrediction,
)
from servant_core.storage import default_model_file

RUN_DESCRIPTION = (
    "Listen and look through the microphone and camera, recognise the scene and move the arm "
    "to the pose taught for it. Opens the terminal application; with --headless, prints one "
    'line per event instead ("CoffeeScene detected", what was heard and seen). Stop with Ctrl-C '
    "or --duration."
)
DEMO_DESCRIPTION = (
    "A walk through built-in scenes (a café, a gym, a street), made up on the spot: no "
    "microphone, camera or arm needed. Opens the terminal application; with --headless, prints "
    "one line per event instead. Stop with Ctrl-C or --duration."
)


def register(subparsers: Any) -> None:
    run = subparsers.add_parser(
        "run",
        help="recognise scenes from the live microphone and camera",
        description=RUN_DESCRIPTION,
    )
    run.add_argument(
        "--model",
        help="model file from `servant train`; retrains are saved back to it (default: the one "
        "teach mode saved in the data dir, if any, else senses only)",
    )
    run.add_argument("--mic", help="input device index or name (default: the system's default)")
    run.add_argument("--rate", type=int, help="sample rate in Hz (default: the device's own)")
    run.add_argument("--no-mic", action="store_true", help="do not listen")
    run.add_argument("--camera", default="0", help="camera index, video file or image pattern")
    run.add_argument("--no-camera", action="store_true", help="do not look")
    run.add_argument("--list-devices", action="store_true", help="list input devices and exit")
    _common(run)
    run.set_defaults(handler=run_live)

    demo = subparsers.add_parser(
        "demo",
        help="the built-in demo scenes (no microphone or camera needed)",
        description=DEMO_DESCRIPTION,
    )
    demo.add_argument("--seed", type=int, default=0, help="seed of the synthesised scenes")
    demo.add_argument(
        "--fast", action="store_true", help="as fast as possible, on a simulated clock"
    )
    _common(demo)
    demo.set_defaults(handler=run_demo)


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--headless", action="store_true", help="print lines, no terminal UI")
    parser.add_argument("--duration", type=float, help="stop after this many seconds")
    parser.add_argument("--json", action="store_true", help="one JSON object per event")


def run_live(args: argparse.Namespace) -> int:
    if args.list_devices:
        from servant_core.capture.microphone import list_input_devices

        for device in list_input_devices():
            mark = "*" if device.is_default else " "
            rate = f"{device.channels} ch, {device.default_rate} Hz"
            print(f"{mark} {device.index:3d}  {device.name}  ({rate})")
        return 0
    return _run(build_live_engine(live_settings(args)), args)


def live_settings(args: argparse.Namespace | None = None) -> LiveSettings:
    """`servant run`'s options; None (`servant` alone): the devices chosen in Settings.

    Without `--model`, the model that teach mode and the library screen last saved is loaded
    (`default_model_file()`, if there is one yet) and retrains and fold-ins are saved back to it.
    """
    default = default_model_file()
    taught = default if default.is_file() else None
    if args is None:
        from servant_core.settings import load_settings

        chosen = load_settings()
        return LiveSettings(
            model=taught,
            model_path=default,
            microphone=chosen.audio_device,
            camera=chosen.camera if chosen.camera is not None else 0,
        )
    return LiveSettings(
        model=args.model or taught,
        model_path=args.model or default,
        microphone=args.mic,
        rate=args.rate,
        use_microphone=not args.no_mic,
        camera=None if args.no_camera else args.camera,
    )


def run_demo(args: argparse.Namespace) -> int:
    engine = build_demo_engine(args.seed, realtime=not args.fast)
    if args.fast:
        engine.subscribe(_printer(args.json))
        engine.run_until(args.duration if args.duration is not None else 95.0)
        return 0
    return _run(engine, args)


def _run(engine: Engine, args: argparse.Namespace) -> int:
    if not args.headless:
        print("servant: the terminal UI is not attached here; running headless", file=sys.stderr)
    engine.subscribe(_printer(args.json))
    engine.start()
    try:
        while engine.running and (args.duration is None or engine.clock() < args.duration):
            time.sleep(0.05)
    except KeyboardInterrupt:
        pass
    finally:
        engine.stop()
    return 0


def _printer(as_json: bool) -> Any:
    def show(event: Event) -> None:
        text = _event_json(event) if as_json else _event_line(event)
        if text is not None:
            print(text, flush=True)

    return show


def _event_line(event: Event) -> str | None:
    """The line a person reads for an event, or None for events too frequent to print."""
    at = f"[{event.t:7.2f}]"
    if isinstance(event, (Decision, AcousticPrediction, VisualPrediction)):
        confidence = confidence_text(event.confidence, event.confidence_unit)
        if isinstance(event, Decision):
            return f"{at} {event.line}  confidence {confidence}"
        if isinstance(event, AcousticPrediction):
            return f"{at} heard {place(event.scene)}  acoustic confidence {confidence}"
        return f"{at} saw {place(event.scene)}  visual confidence {confidence}"
    if isinstance(event, UnknownScene):
        return f"{at} unknown {event.sense} ({event.window_id}), nearest: {event.nearest_scene}"
    if isinstance(event, DeviceStatus):
        return f"{at} {event.device} {'ok' if event.ok else 'PROBLEM'}: {event.message}"
    if isinstance(event, ErrorEvent):
        return f"{at} error: {event.message}"
    if isinstance(event, ArmState):
        return f"{at} arm {'armed' if event.armed else 'disarmed'} {event.angles}"
    return None


def _event_json(event: Event) -> str | None:
    if _event_line(event) is None:
        return None
    payload = {"event": type(event).__name__, **dataclasses.asdict(event)}
    return json.dumps(payload, default=lambda v: v.tolist() if hasattr(v, "tolist") else str(v))
