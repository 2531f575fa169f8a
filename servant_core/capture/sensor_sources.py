"""The motion and ambient sources a command line names: a serial port, a CSV log or a folder.

`--imu /dev/ttyACM0 --ambient /dev/ttyACM0` is one board on one port (opened once, both
streams read from it); `--imu walk.imu.csv` replays a log; `--imu ROOT` replays every
`*.imu.csv` under ROOT, each labelled by its folder (the library's `ROOT/<scene>/` layout).
"""

from __future__ import annotations

from pathlib import Path

from servant_core.capture.sample_files import SUFFIXES, PacedSamples, replay_sample_files
from servant_core.capture.sensors import SensorBoard, SerialSamples
from servant_core.capture.source import ManualClock
from servant_core.errors import ServantError
from servant_core.storage import walk_files


def is_log(spec: str) -> bool:
    """Whether `spec` names files to replay rather than a serial port."""
    path = Path(spec)
    return (
        path.is_dir()
        or spec.lower().endswith(".csv")
        or (path.is_file() and not path.is_char_device())
    )


def sensor_sources(
    specs: dict[str, str | None],
    *,
    realtime: bool = True,
    clock: ManualClock | None = None,
    follow: ManualClock | None = None,
    loop: bool = False,
) -> dict[str, SerialSamples | PacedSamples]:
    """A source per stream ("imu", "ambient") given a port, a CSV file or a folder; streams
    given None are left out. Replays advance `clock` or follow `follow` (see `PacedSamples`)."""
    boards: dict[str, SensorBoard] = {}
    sources: dict[str, SerialSamples | PacedSamples] = {}
    for kind, spec in specs.items():
        if spec is None:
            continue
        if not is_log(spec):
            sources[kind] = boards.setdefault(spec, SensorBoard(spec)).source(kind)
            continue
        path = Path(spec)
        items: list[tuple[str | None, Path]]
        if path.is_dir():
            files = [f for f in walk_files(path) if f.name.endswith(SUFFIXES[kind])]
            if not files:
                raise ServantError(f"{path}: no {SUFFIXES[kind]} files in it; record some first")
            items = [(f.parent.name, f) for f in files]
        else:
            items = [(None, path)]
        sources[kind] = replay_sample_files(
            items, kind, realtime=realtime, clock=clock, follow=follow, loop=loop
        )
    return sources
