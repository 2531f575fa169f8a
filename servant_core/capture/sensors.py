"""The sensor board on a serial port: motion (an MPU-6050) and ambient values, as text lines.

An Arduino running `docs/sensor_board.ino` sends ASCII lines (`docs/sensors.md`):
`I,<ms>,<ax>,<ay>,<az>,<gx>,<gy>,<gz>` (m/s², deg/s), `A,<ms>,<lux>,<celsius>,<hPa>`, `# comment`.
`SensorBoard(port)` owns the port; `board.source("imu")` and `board.source("ambient")` are
`SampleSource`s over it, readable from different threads; `measured_rate` is the stamps' rate. A
line that does not parse is skipped and counted (`bad_lines`), never a fault; a vanished port is
one `ServantError`."""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np

from servant_core.errors import ServantError
from servant_core.numbers import MAX_STAMP
from servant_core.serial_port import PORT_ERRORS, open_serial

IMU_CHANNELS = ("ax", "ay", "az", "gx", "gy", "gz")
AMBIENT_CHANNELS = ("lux", "celsius", "hpa")
# the stream each line tag carries, and that stream's columns
STREAMS: dict[str, tuple[str, tuple[str, ...]]] = {
    "I": ("imu", IMU_CHANNELS),
    "A": ("ambient", AMBIENT_CHANNELS),
}
TAGS = {kind: tag for tag, (kind, _) in STREAMS.items()}
# What each channel can read, in the format's units, with room to spare: a phone's or an
# MPU-6050's accelerometer spans ±16 g (157 m/s²) and its gyroscope ±2000 deg/s; sunlight is
# some 120,000 lux; barometers read 300–1100 hPa. A value beyond is line noise or a damaged
# log, and would overflow the features' squares and sums (1e307 lux, 3.4e38 m/s²).
ACCELERATION_LIMIT = (-2000.0, 2000.0)
ROTATION_LIMIT = (-20000.0, 20000.0)
CHANNEL_LIMITS: dict[str, tuple[float, float]] = {
    "ax": ACCELERATION_LIMIT,
    "ay": ACCELERATION_LIMIT,
    "az": ACCELERATION_LIMIT,
    "gx": ROTATION_LIMIT,
    "gy": ROTATION_LIMIT,
    "gz": ROTATION_LIMIT,
    "lux": (0.0, 1e6),
    "celsius": (-100.0, 200.0),
    "hpa": (0.0, 2000.0),
}
CHANNELS = {kind: channels for kind, channels in STREAMS.values()}


def rows_in_range(values: np.ndarray, kind: str) -> np.ndarray:
    """Which rows of (n, channels) readings of stream `kind` are numbers each within its
    channel's `CHANNEL_LIMITS` (NaN and infinity are not)."""
    low, high = np.array([CHANNEL_LIMITS[c] for c in CHANNELS[kind]]).T
    values = np.asarray(values, dtype=np.float64)
    return np.all((values >= low) & (values <= high), axis=1)


IMU_RATE = 50  # Hz: above twice the 20 Hz top of the vibration band the features look at
AMBIENT_RATE = 2  # Hz: light, temperature and pressure change slowly
RATES = {"imu": IMU_RATE, "ambient": AMBIENT_RATE}
DEFAULT_BAUDRATE = 115200  # 50 lines of ~50 bytes a second use a quarter of it
MAX_LINE_BYTES = 200  # the longest valid line is under 100 bytes: the rest is noise
BUFFER_SECONDS = 30.0  # rows kept for a stream nobody reads for a while; older ones are dropped


@dataclass(frozen=True)
class SensorLine:
    kind: str  # "imu" or "ambient"
    millis: int
    values: tuple[float, ...]


def parse_line(line: bytes) -> SensorLine | None:
    """One line of the board (without or with its line ending): a reading, or None for a
    comment or an empty line. Anything else raises ValueError."""
    text = line.decode("ascii").strip()
    if not text or text.startswith("#"):
        return None
    fields = text.split(",")
    if fields[0] not in STREAMS:
        raise ValueError(f"unknown line tag {fields[0][:8]!r}")
    kind, channels = STREAMS[fields[0]]
    if len(fields) != 2 + len(channels):
        raise ValueError(f"{len(fields)} fields, not {2 + len(channels)}")
    millis = int(fields[1])
    values = tuple(float(f) for f in fields[2:])
    if not 0 <= millis < MAX_STAMP:
        raise ValueError("a time stamp out of range")
    if not rows_in_range(np.array([values]), kind)[0]:
        raise ValueError("a value beyond what the sensor reads")
    return SensorLine(kind, millis, values)


def format_line(kind: str, millis: int, values: np.ndarray | tuple[float, ...]) -> bytes:
    """The line the board sends for a reading (what the sketch prints, to the same decimals)."""
    decimals = {"imu": 3, "ambient": 2}[kind]
    numbers = ",".join(f"{float(v):.{decimals}f}" for v in values)
    return f"{TAGS[kind]},{int(millis)},{numbers}\n".encode("ascii")


class SensorBoard:
    """The board's serial port, opened while one of its sources is open; lines parsed into rows
    per stream. `bad_lines` counts the lines skipped since construction."""

    def __init__(
        self,
        port: str,
        *,
        baudrate: int = DEFAULT_BAUDRATE,
        imu_rate: int = IMU_RATE,
        ambient_rate: int = AMBIENT_RATE,
    ) -> None:
        self.port = port
        self.baudrate = baudrate
        self.rates = {"imu": imu_rate, "ambient": ambient_rate}
        self.bad_lines = 0
        self._handle: Any = None
        self._users: set[str] = set()
        self._pending = b""
        self._rows: dict[str, deque[tuple[float, ...]]] = {
            kind: deque(maxlen=max(1, int(BUFFER_SECONDS * rate)))
            for kind, rate in self.rates.items()
        }
        # (first millis, latest millis, lines) of each stream since it was opened
        self._stamps: dict[str, tuple[int, int, int]] = {}
        self._lock = threading.Lock()

    def measured_rate(self, kind: str) -> float | None:
        """Lines a second of a stream by the board's own clock (None before two lines): a
        sketch set to another rate than `rates` says shows here."""
        with self._lock:
            first, latest, count = self._stamps.get(kind, (0, 0, 0))
        return (count - 1) * 1000.0 / (latest - first) if count > 1 and latest > first else None

    def source(self, kind: str) -> SerialSamples:
        if kind not in CHANNELS:
            raise ValueError(f"kind must be one of {sorted(CHANNELS)}")
        return SerialSamples(self, kind)

    def open(self, kind: str) -> None:
        with self._lock:
            if self._handle is None:
                self._connect()
            self._users.add(kind)

    def release(self, kind: str) -> None:
        with self._lock:
            self._users.discard(kind)
            self._rows[kind].clear()
            self._stamps.pop(kind, None)
            if not self._users:
                self._disconnect()

    def take(self, kind: str, timeout: float) -> np.ndarray | None:
        """The rows of `kind` received so far (float32, (n, channels)), waiting up to `timeout`
        seconds for the first; None if none came."""
        if kind not in self._users:
            raise ValueError(f"the {kind} source is read before it is opened")
        deadline = time.monotonic() + max(0.0, timeout)
        while True:
            with self._lock:
                if self._handle is None:
                    self._connect()  # the other stream's fault closed the port: try again
                rows = self._rows[kind]
                if rows:
                    block = np.asarray(rows, dtype=np.float32)
                    rows.clear()
                    return block
                self._pump()
                if self._rows[kind]:
                    continue
            if time.monotonic() >= deadline:
                return None

    def _connect(self) -> None:
        self._pending = b""
        self._handle = open_serial(self.port, self.baudrate)

    def _disconnect(self) -> None:
        if self._handle is not None:
            try:
                self._handle.close()
            except PORT_ERRORS:
                pass  # the port is gone already; closing is only tidying up
        self._handle = None

    def _pump(self) -> None:
        """Read what the port has (waiting at most its short timeout) and parse whole lines."""
        handle = self._handle
        try:
            data = handle.read(max(1, handle.in_waiting))
        except PORT_ERRORS as exc:
            self._disconnect()
            reason = exc.args[1] if len(exc.args) == 2 else str(exc)
            raise ServantError(
                f"{self.port}: the sensor board was lost ({reason}); reconnect it (Servant "
                "reopens it by itself)"
            ) from exc
        *lines, self._pending = (self._pending + data).split(b"\n")
        if len(self._pending) > MAX_LINE_BYTES:
            self._pending = b""
            self.bad_lines += 1
        for line in lines:
            try:
                reading = parse_line(line)
            except (ValueError, UnicodeDecodeError):
                self.bad_lines += 1
                continue
            if reading is not None and reading.kind in self._users:
                self._rows[reading.kind].append(reading.values)
                first, _, count = self._stamps.get(reading.kind, (reading.millis, 0, 0))
                self._stamps[reading.kind] = (first, reading.millis, count + 1)


class SerialSamples:
    """One stream of a `SensorBoard` as a `SampleSource` (live: a fault is reopened later)."""

    def __init__(self, board: SensorBoard, kind: str) -> None:
        self.board = board
        self.kind = kind
        self.name = f"{kind} sensor on {board.port}"
        self.rate = board.rates[kind]
        self.channels = CHANNELS[kind]
        self.live = True

    def open(self) -> None:
        self.board.open(self.kind)

    def read(self, timeout: float) -> np.ndarray | None:
        return self.board.take(self.kind, timeout)

    @property
    def exhausted(self) -> bool:
        return False

    @property
    def bad_lines(self) -> int:
        """Lines the board sent that were not readings (both streams), since it was made."""
        return self.board.bad_lines

    def close(self) -> None:
        self.board.release(self.kind)
