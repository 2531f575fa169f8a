"""`servant emulate-sensors`: the motion and ambient sensor board, emulated on a pseudo-terminal."""

from __future__ import annotations

import argparse

from servant_core.capture.sensors import AMBIENT_RATE, IMU_RATE
from servant_core.cli import serve_until_stopped
from servant_core.cli.options import bounded_int, finite_float

MAX_EMULATE_S = 7 * 24 * 3600.0


def register(subparsers: argparse._SubParsersAction) -> None:
    emulate = subparsers.add_parser(
        "emulate-sensors",
        description="Streams the lines of docs/sensor_board.ino (docs/sensors.md): synthesised "
        "motion and ambient values of the scene a script names, over and over.",
    )
    emulate.add_argument(
        "--script",
        help="scenes and their seconds, e.g. coffee:20,gym:20,street:55 (default: the demo's walk)",
    )
    emulate.add_argument("--seed", type=bounded_int(0, 2**31 - 1), default=0, help="random seed")
    emulate.add_argument("--imu-rate", type=bounded_int(1, 1000), default=IMU_RATE, help="Hz")
    emulate.add_argument(
        "--ambient-rate", type=bounded_int(1, 100), default=AMBIENT_RATE, help="Hz"
    )
    emulate.add_argument("--link", help="also make this path a symlink to the port (a stable name)")
    emulate.add_argument(
        "--seconds",
        type=finite_float(0.0, MAX_EMULATE_S),
        help="stop after this many seconds (default: Ctrl-C)",
    )
    emulate.set_defaults(handler=run_emulate_sensors)


def run_emulate_sensors(args: argparse.Namespace) -> int:
    from servant_core.demo.motion_synth import SCENE_AMBIENT
    from servant_core.demo.scenes import segment_at
    from servant_core.demo.sensor_emulator import SensorEmulator, parse_script, script_scene
    from servant_core.errors import ServantError
    from servant_core.pty_port import announce

    if args.script:
        script = parse_script(args.script)
        unknown = sorted({scene for scene, _ in script} - set(SCENE_AMBIENT))
        if unknown:
            raise ServantError(
                f"no synthesised scene named {unknown[0]!r}; choose from "
                f"{', '.join(sorted(SCENE_AMBIENT))}"
            )
        scene_at = script_scene(script)
    else:
        scene_at = lambda t: segment_at(t).sound  # noqa: E731  # the walk the demo plays
    emulator = SensorEmulator(
        scene_at, seed=args.seed, imu_rate=args.imu_rate, ambient_rate=args.ambient_rate
    )
    port = emulator.start(args.link)
    withdraw = announce(port, "Servant's emulated sensor board (servant emulate-sensors)")

    def stop_serving() -> None:
        withdraw()
        emulator.stop()

    return serve_until_stopped(
        stop_serving,
        f"Emulating the sensor board on {port} ({args.imu_rate} Hz motion, "
        f"{args.ambient_rate} Hz ambient); connect with `--imu {port}`. Ctrl-C stops.",
        args.seconds,
    )
