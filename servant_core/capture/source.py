"""What the engine asks of a sense: audio and sample sources give blocks, frame sources pictures.

All kinds are thin classes around a device or a file. They raise `ServantError` (one line: which
device or file, what is wrong, what to do) when they fail; the engine reports it once and keeps
running on the other senses, reopening the failed one from time to time. The engine's time is
any callable returning seconds; `ManualClock` is the clock of a run as fast as possible: the
replaying source advances it by each block's duration, so event times are stream times.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class AudioSource(Protocol):
    """Mono float32 audio in consecutive blocks.

    `name` for messages; `rate` in samples a second (known after `open`); `open()` acquires the
    device or file; `read(timeout)` → the next 1-D float32 block, or None after `timeout` s;
    `exhausted` once a replay has nothing more; `live`: a device (a fault closes it, the engine
    reopens it later), else a replay (a fault is one bad file, the next goes on); `rate_note`: what
    the engine says on opening instead of "listening at <rate> Hz" (None: that); `close()` is safe
    twice. `open` and `read` raise ServantError on a fault (device gone, corrupt file).
    """

    name: str
    rate: int
    live: bool
    rate_note: str | None

    def open(self) -> None: ...
    def read(self, timeout: float) -> np.ndarray | None: ...
    @property
    def exhausted(self) -> bool: ...
    def close(self) -> None: ...


@runtime_checkable
class SampleSource(Protocol):
    """Multichannel float32 samples in consecutive blocks: a motion or an ambient sensor.

    The same contract as `AudioSource`, except that a block is a 2-D array (n, channels) whose
    columns `channels` names (e.g. ("ax", "ay", "az", "gx", "gy", "gz")), `rate` is rows
    per second (a sensor's rate: tens of hertz for motion, one or two for ambient values), and
    `bad_lines` counts the lines a board sent that were not readings (0 from a file).
    """

    name: str
    rate: int
    live: bool
    channels: tuple[str, ...]

    @property
    def bad_lines(self) -> int: ...

    def open(self) -> None: ...
    def read(self, timeout: float) -> np.ndarray | None: ...
    @property
    def exhausted(self) -> bool: ...
    def close(self) -> None: ...


@runtime_checkable
class FrameSource(Protocol):
    """Pictures on demand, as BGR uint8 arrays (OpenCV's order).

    - `open()`: raises ServantError when the camera or file cannot be opened.
    - `read()`: the current frame; raises ServantError when no frame comes.
    - `close()`: release; safe to call twice.
    """

    name: str

    def open(self) -> None: ...
    def read(self) -> np.ndarray: ...
    def close(self) -> None: ...


class ManualClock:
    """A clock that moves only when told to; thread-safe. Calling it returns the time in seconds."""

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)
        self._lock = threading.Lock()

    def __call__(self) -> float:
        with self._lock:
            return self._t

    def advance(self, seconds: float) -> float:
        with self._lock:
            self._t += seconds
            return self._t


class MonotonicClock:
    """Seconds since construction, from `time.monotonic` (the engine's default clock)."""

    def __init__(self) -> None:
        self._start = time.monotonic()

    def __call__(self) -> float:
        return time.monotonic() - self._start
