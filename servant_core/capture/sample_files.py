"""Motion and ambient recordings as CSV files: read (as phone sensor-logger apps export them),
written (as teach mode keeps them), and replayed as a `SampleSource`.

A header row, then a row per reading: time, then the channels. Motion (`*.imu.csv`): ax, ay, az
(m/s²), gx, gy, gz (deg/s); ambient (`*.ambient.csv`): lux, celsius, hpa. Common apps' headers are
accepted (`ALIASES`) and a unit in brackets converts. Readings are resampled onto a uniform grid at
the sensor rate; a pause over `MAX_GAP_S` splits the file. Rows that do not parse are skipped and
counted; a file with no usable rows is one `ServantError`."""

from __future__ import annotations

import csv
import io
import math
import re
import time
from array import array
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servant_core.audio import DEFAULT_WINDOW_SECONDS
from servant_core.capture.replay import Clip, PacedAudio
from servant_core.capture.sensors import CHANNELS, RATES, rows_in_range
from servant_core.capture.source import ManualClock
from servant_core.errors import ServantError
from servant_core.library import sample_log_text
from servant_core.numbers import MAX_STAMP
from servant_core.senses import SAMPLE_SENSES
from servant_core.storage import atomic_write_text, open_regular_file, os_reason

SUFFIXES = {s.stream: s.suffixes[0] for s in SAMPLE_SENSES.values() if s.stream}
MAX_GAP_S = 1.0  # longer pauses in a log are not interpolated across
# Four hours of 100 Hz motion is some 1.5 million rows, 80 MB of text; a file, its rows and
# its resampled readings stay within a few hundred megabytes of memory below these bounds.
MAX_FILE_BYTES = 128 * 1024 * 1024
MAX_ROWS = 2_000_000
MAX_LOG_SECONDS = 4 * 3600.0  # of readings, once resampled: pauses under MAX_GAP_S count
G = 9.80665

ALIASES: dict[str, tuple[str, ...]] = {
    "time": ("time", "t", "timestamp", "secondselapsed", "elapsed", "timens", "timems"),
    "ax": ("ax", "accx", "accelx", "accelerationx", "accelerometerx", "linearaccx"),
    "ay": ("ay", "accy", "accely", "accelerationy", "accelerometery", "linearaccy"),
    "az": ("az", "accz", "accelz", "accelerationz", "accelerometerz", "linearaccz"),
    "gx": ("gx", "gyrx", "gyrox", "gyroscopex", "rotationratex", "wx"),
    "gy": ("gy", "gyry", "gyroy", "gyroscopey", "rotationratey", "wy"),
    "gz": ("gz", "gyrz", "gyroz", "gyroscopez", "rotationratez", "wz"),
    "lux": ("lux", "light", "illuminance", "lightlux", "illuminancelux", "lx"),
    "celsius": ("celsius", "temp", "temperature", "tempc", "temperaturec", "degc"),
    "hpa": ("hpa", "pressure", "pressurehpa", "baro", "barometer", "airpressure", "mbar"),
}
# a unit in brackets, and the factor to the file format's unit
UNIT_FACTORS = {
    "g": G,
    "rad/s": 180.0 / math.pi,
    "pa": 0.01,
    "kpa": 10.0,
}


def _normalised(header: str) -> tuple[str, str]:
    """(name, unit): lower case without brackets, spaces or punctuation; the bracketed unit."""
    unit = re.search(r"[\(\[]([^\)\]]*)[\)\]]", header)
    name = re.sub(r"[\(\[][^\)\]]*[\)\]]", "", header.lower())
    return re.sub(r"[^a-z0-9]", "", name), (unit.group(1).strip().lower() if unit else "")


@dataclass(frozen=True)
class SampleLog:
    """A file's readings: `times` in seconds (n,), `values` (n, channels) in the format's units,
    and how many rows were skipped."""

    times: np.ndarray
    values: np.ndarray
    skipped: int
    path: Path | None = None


def read_sample_csv(path: str | Path, kind: str) -> SampleLog:
    """The readings of a motion (`kind="imu"`) or ambient CSV, sorted by time."""
    path = Path(path)
    channels = CHANNELS[kind]
    with open_regular_file(path, f"{kind} CSV file") as handle:
        try:
            if Path(path).stat().st_size > MAX_FILE_BYTES:
                raise ServantError(f"{path}: larger than any sensor log; split it into files")
            text = io.TextIOWrapper(handle, encoding="utf-8-sig", errors="replace", newline="")
            rows = csv.reader(text)
            header = next(rows, None)
            if header is None:
                raise ServantError(f"{path}: empty; a {kind} CSV starts with a header row")
            columns, factors, time_unit = _columns(path, header, channels)
            times: list[int | float] = []
            values = array("d")  # flat: a Python list of lists takes ten times the memory
            skipped = 0
            for row in rows:
                try:
                    stamp = _stamp(row[columns[0]])
                    numbers = [float(row[c]) for c in columns[1:]]
                except (ValueError, IndexError):
                    skipped += 1
                    continue
                if not all(math.isfinite(v) for v in (stamp, *numbers)):
                    skipped += 1
                    continue
                if len(times) >= MAX_ROWS:
                    raise ServantError(
                        f"{path}: more than {MAX_ROWS:,} readings; split it into shorter logs"
                    )
                times.append(stamp)
                values.extend(numbers)
        except OSError as exc:
            raise ServantError(f"{path}: cannot read the file ({os_reason(exc)})") from None
        except csv.Error as exc:
            raise ServantError(f"{path}: not a CSV file ({exc}); export it as CSV") from None
    if len(times) < 2:
        raise ServantError(f"{path}: fewer than two readings that parse; record a longer log")
    first = min(times)
    # from the first stamp on, in Python numbers: nanosecond stamps (~1.7e18) are exact as
    # integers but lose a quarter of a microsecond as floats
    t = np.asarray([stamp - first for stamp in times], dtype=np.float64)
    order = np.argsort(t, kind="stable")
    v = np.frombuffer(values, dtype=np.float64).reshape(len(times), -1)[order] * np.asarray(factors)
    # in range in the format's units, after the unit's conversion, before the cast to float32
    usable = rows_in_range(v, kind)
    if np.count_nonzero(usable) < 2:
        raise ServantError(
            f"{path}: fewer than two readings within what a {kind} sensor reads; "
            "check the columns' units"
        )
    t, v = t[order][usable], v[usable]
    skipped += len(usable) - int(np.count_nonzero(usable))
    return SampleLog(_seconds(t, time_unit), v.astype(np.float32), skipped, path)


def _stamp(text: str) -> int | float:
    """A time stamp: an integer kept exact, else a float; ValueError beyond 64 bits (no unit
    of a logger's clock needs more, and the differences of larger ones overflow floats)."""
    try:
        stamp: int | float = int(text)
    except ValueError:
        stamp = float(text)
    if not -MAX_STAMP < stamp < MAX_STAMP:
        raise ValueError(f"time stamp {text[:20]} out of range")
    return stamp


def _columns(
    path: Path, header: Sequence[str], channels: tuple[str, ...]
) -> tuple[list[int], list[float], str]:
    """Column of time and of each channel, each channel's unit factor, and the time's unit."""
    found = [_normalised(h) for h in header]
    columns: list[int] = []
    factors: list[float] = []
    time_unit = ""
    for wanted in ("time", *channels):
        match = [i for i, (name, _) in enumerate(found) if name in ALIASES[wanted]]
        if not match:
            spellings = ", ".join(ALIASES[wanted][:4])
            raise ServantError(
                f"{path}: no {wanted} column (header: {','.join(header)[:80]}); name it one of "
                f"{spellings}"
            )
        name, unit = found[match[0]]
        columns.append(match[0])
        if wanted == "time":
            time_unit = unit or next((u for u in ("ns", "ms") if name.endswith(u)), "")
        else:
            factors.append(UNIT_FACTORS.get(unit, 1.0))
    return columns, factors, time_unit


def _seconds(t: np.ndarray, unit: str) -> np.ndarray:
    if unit in ("ns", "ms", "us"):
        scale = {"ns": 1e-9, "us": 1e-6, "ms": 1e-3}[unit]
    else:
        steps = np.diff(t)
        steps = steps[steps > 0]
        scale = 1e-9 if len(steps) and np.median(steps) >= 1e4 else 1.0
    return t * scale


def resampled(log: SampleLog, rate: int) -> list[np.ndarray]:
    """The log on a uniform grid at `rate` (linear interpolation), one array per stretch without
    a pause longer than `MAX_GAP_S`; stretches shorter than one sample period are dropped."""
    t, v = log.times, log.values.astype(np.float64)
    keep = np.concatenate([[True], np.diff(t) > 0])  # duplicate stamps: the first reading
    t, v = t[keep], v[keep]
    cuts = np.flatnonzero(np.diff(t) > MAX_GAP_S) + 1
    # the grid's length is known before any of it is made: rows 0.99 s apart are 99 samples
    # each at 100 Hz, and a few megabytes of them would otherwise be gigabytes
    starts, ends = t[np.r_[0, cuts]], t[np.r_[cuts - 1, len(t) - 1]]
    if np.sum(ends - starts) > MAX_LOG_SECONDS:
        raise ServantError(
            f"{log.path or 'a sensor log'}: its readings span more than "
            f"{MAX_LOG_SECONDS / 3600:g} hours; split it into shorter logs"
        )
    pieces = []
    for times, values in zip(np.split(t, cuts), np.split(v, cuts), strict=True):
        # the last reading stands for one period after it: 10 readings at 2 Hz are 5 s
        grid = times[0] + np.arange(int(np.floor((times[-1] - times[0]) * rate + 1e-6)) + 1) / rate
        if len(grid) < 2:
            continue
        pieces.append(
            np.stack([np.interp(grid, times, values[:, c]) for c in range(v.shape[1])], axis=1)
        )
    return [p.astype(np.float32) for p in pieces]


def read_samples(path: str | Path, kind: str, rate: int | None = None) -> np.ndarray:
    """A whole file at `rate` (default: the sensor's), its stretches joined: (n, channels)."""
    pieces = resampled(read_sample_csv(path, kind), rate or RATES[kind])
    if not pieces:
        raise ServantError(f"{path}: its readings span less than one sample; record a longer log")
    return np.concatenate(pieces)


def cut_sample_windows(
    samples: np.ndarray, rate: int, seconds: float = DEFAULT_WINDOW_SECONDS
) -> list[np.ndarray]:
    """Consecutive whole windows of `seconds` of (n, channels) samples; the rest is dropped."""
    length = int(round(rate * seconds))
    return [samples[i : i + length] for i in range(0, len(samples) - length + 1, length)]


def write_sample_csv(
    path: str | Path, samples: np.ndarray, rate: int, kind: str, start: float = 0.0
) -> Path:
    """Write (n, channels) samples at `rate` as a CSV this module reads back, atomically."""
    return atomic_write_text(path, sample_log_text(samples, rate, CHANNELS[kind], start))


class PacedSamples(PacedAudio):
    """`PacedAudio`'s pacing over multichannel clips: a `SampleSource`.

    `follow`, a clock (another source's `ManualClock`), keeps an as-fast-as-possible replay in
    step with it: rows are given only up to its time. Only one replay of a run should advance a
    `ManualClock` (`clock=`); the others follow it.
    """

    def __init__(
        self,
        clips: Iterable[Clip | ServantError],
        rate: int,
        channels: tuple[str, ...],
        *,
        follow: ManualClock | None = None,
        **options: object,
    ) -> None:
        super().__init__(clips, rate, **options)  # type: ignore[arg-type]
        self.channels = channels
        self.bad_lines = 0  # rows come from files, not from a board's lines
        self.follow = follow

    def read(self, timeout: float) -> np.ndarray | None:
        if self.follow is not None and not self.realtime:
            due = int(math.floor(self.follow() * self.rate + 1e-9)) - self._produced
            if due < self.block:
                time.sleep(min(timeout, 0.001))  # the followed source has not got there yet
                return None
        return super().read(timeout)


def file_clips(
    items: Sequence[tuple[str | None, Path]], kind: str, rate: int, loop: bool
) -> Iterator[Clip | ServantError]:
    """Each file in turn, resampled (one in memory); a bad one yields its ServantError."""
    while items:
        for label, path in items:
            try:
                for piece in resampled(read_sample_csv(path, kind), rate):
                    yield Clip(label, piece)
            except ServantError as error:
                yield error
        if not loop:
            return


def replay_sample_files(
    files: Sequence[str | Path] | Sequence[tuple[str | None, Path]],
    kind: str,
    rate: int | None = None,
    *,
    realtime: bool = True,
    clock: ManualClock | None = None,
    follow: ManualClock | None = None,
    loop: bool = False,
    block_seconds: float = 0.2,
) -> PacedSamples:
    """A `SampleSource` playing motion (`kind="imu"`) or ambient CSVs one after another; items
    are paths, or (scene, path) pairs so that `current_label` says the scene."""
    items = [f if isinstance(f, tuple) else (None, Path(f)) for f in files]
    rate = rate or RATES[kind]
    name = f"replay {items[0][1].name}" if len(items) == 1 else f"replay of {len(items)} files"
    return PacedSamples(
        file_clips(items, kind, rate, loop),
        rate,
        CHANNELS[kind],
        follow=follow,
        realtime=realtime,
        clock=clock,
        block_seconds=block_seconds,
        name=name,
    )
