"""The device side of the sense loop: opening, reopening and reading the microphone and camera.

`Hearing` keeps the last `RING_SECONDS` of audio in a ring, makes a spectrum frame ~30 times per
second of audio and cuts consecutive windows, handing each to the engine. `Sight` grabs a
picture when asked. Both report their device's state on the bus once per change, and a live
device that failed is reopened every `reopen_seconds`; a replay's fault is one bad file, and the
replay goes on with the next.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from servant_core.capture.ring import RingBuffer
from servant_core.capture.source import AudioSource, FrameSource, SampleSource
from servant_core.engine.bus import EventBus
from servant_core.engine.stream_watch import News, StreamWatch
from servant_core.errors import ServantError
from servant_core.events import SensorFrame, SpectrumFrame
from servant_core.senses import Sense

SPECTRUM_SIZE = 2048
SPECTRUM_FPS = 30.0
RING_SECONDS = 30.0  # what the ring holds: a window being cut while teach mode records 5 s
# How often a recording waiting for its seconds looks whether it was asked to stop: the front
# end's request is a plain event, which cannot wake the wait itself (teach mode's `q` waited out
# the whole timeout, 12 s of blank terminal).
STOP_CHECK_SECONDS = 0.05


def stopped_text(seconds: float) -> str:
    return f"recording: stopped before its {seconds:g} s were in, and not kept"


def spectrum_db(samples: np.ndarray, rate: int) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies in Hz, magnitude in dB re full scale) of a Hann-windowed stretch of samples.

    A full-scale sine reads 0 dB; silence is floored at −120 dB.
    """
    n = len(samples)
    hann = np.hanning(n)
    magnitude = np.abs(np.fft.rfft(samples * hann)) * 2.0 / hann.sum()
    return np.fft.rfftfreq(n, 1.0 / rate), 20.0 * np.log10(np.maximum(magnitude, 1e-6))


@dataclass(frozen=True)
class DeviceMakers:
    """How a live engine opens the camera or microphone the Settings name (a device value as
    the settings hold it: an index, a name, a path, or None for the default)."""

    camera: Callable[[int | str | None], FrameSource]
    microphone: Callable[[int | str | None], AudioSource]


class Hearing:
    """The audio source, its ring, its spectra and its windows.

    `on_window(window, rate)` is called on the sense thread for each `window_seconds` of audio.
    """

    def __init__(
        self,
        source: AudioSource,
        bus: EventBus,
        on_window: Callable[[np.ndarray, int], None],
        *,
        window_seconds: float,
        reopen_seconds: float,
        spectrum_fps: float = SPECTRUM_FPS,
        spectrum_size: int = SPECTRUM_SIZE,
    ) -> None:
        self.source = source
        self.bus = bus
        self.on_window = on_window
        self.window_seconds = window_seconds
        self.reopen_seconds = reopen_seconds
        self.spectrum_fps = spectrum_fps
        self.spectrum_size = spectrum_size
        self.ok = False
        self.ring: RingBuffer | None = None
        self._retry_at = 0.0
        self._next_window_end = 0
        self._next_spectrum_at = 0

    @property
    def rate(self) -> int:
        """The rate of the blocks; 0 while the source is not working."""
        return self.source.rate if self.ok else 0

    def open(self) -> None:
        try:
            self.source.open()
        except ServantError as error:
            self.ok = False
            self._retry_at = self.bus.clock() + self.reopen_seconds
            self.bus.report("microphone", False, str(error))
            return
        rate = self.source.rate
        if self.ring is None or self.ring.capacity != int(rate * RING_SECONDS):
            self.ring = RingBuffer(int(rate * RING_SECONDS))
        # Windows start afresh after (re)opening: never stitch audio from both sides of a gap.
        self._next_window_end = self.ring.total + int(round(self.window_seconds * rate))
        self._next_spectrum_at = self.ring.total
        self.ok = True
        note = self.source.rate_note or f"{self.source.name}: listening at {rate} Hz"
        self.bus.report("microphone", True, note)

    def close(self) -> None:
        self.source.close()
        self.ok = False

    def replace(self, source: AudioSource) -> None:
        """Listen to `source` from now on (another microphone chosen in Settings)."""
        self.close()
        self.source = source
        self.bus.forget("microphone")
        self.open()

    def reopen_if_due(self, t: float) -> None:
        if not self.ok and t >= self._retry_at:
            self.open()

    def listen(self, timeout: float) -> bool:
        """Take a block if one comes within `timeout`; False once a replay has run out."""
        try:
            block = self.source.read(timeout)
        except ServantError as error:
            self._fault(error)
            block = None
        if block is not None and len(block):
            self._on_block(block)
        elif self.source.exhausted:
            self.bus.report("microphone", False, f"{self.source.name}: finished")
            return False
        return True

    def _fault(self, error: ServantError) -> None:
        """A live device that stopped is closed and reopened later; a replay skips the bad file."""
        if not self.source.live:
            self.bus.error(str(error))
            return
        self.bus.report("microphone", False, str(error))
        self.close()
        self._retry_at = self.bus.clock() + self.reopen_seconds

    def _on_block(self, block: np.ndarray) -> None:
        assert self.ring is not None
        ring, rate = self.ring, self.source.rate
        ring.append(block)
        total = ring.total
        if (
            self.spectrum_fps > 0
            and total >= self._next_spectrum_at
            and total >= self.spectrum_size
        ):
            freqs, db = spectrum_db(ring.latest(self.spectrum_size), rate)
            self.bus.emit(SpectrumFrame(self.bus.clock(), freqs, db))
            hop = max(1, int(rate / self.spectrum_fps))
            self._next_spectrum_at = (total // hop + 1) * hop
        size = int(round(self.window_seconds * rate))
        while total >= self._next_window_end:
            end = self._next_window_end
            self._next_window_end += size
            self.on_window(ring.read(end - size, end), rate)

    def record(
        self, seconds: float, timeout: float | None, cancel: threading.Event | None = None
    ) -> np.ndarray:
        """The next `seconds` of audio from now (blocks until they have arrived, `cancel` is
        set, or the microphone closes)."""
        ring = self.ring
        if ring is None or not self.ok:
            raise ServantError("microphone: no sound to record; check the microphone (see status)")
        count = int(round(seconds * self.source.rate))
        if count > ring.capacity:
            raise ServantError(f"engine: cannot record more than {RING_SECONDS:g} s at once")
        end = ring.total + count
        deadline = time.monotonic() + (timeout if timeout is not None else 2 * seconds + 2)
        while not ring.wait_for(end, STOP_CHECK_SECONDS):
            if cancel is not None and cancel.is_set():
                raise ServantError(stopped_text(seconds))
            # closed (the engine stopping) or failed: no more sound comes into the ring, and
            # sound after a reopening would be stitched to this across the gap
            if not self.ok or time.monotonic() >= deadline:
                raise ServantError(
                    f"{self.source.name}: the sound stopped while recording; try again"
                )
        return ring.read(end - count, end)


class Sight:
    """The camera: pictures on demand, from the sense thread or a front end's (one at a time)."""

    def __init__(self, source: FrameSource, bus: EventBus, *, reopen_seconds: float) -> None:
        self.source = source
        self.bus = bus
        self.reopen_seconds = reopen_seconds
        self.ok = False
        self._retry_at = 0.0
        self._lock = threading.Lock()

    def open(self) -> None:
        with self._lock:
            self._open()

    def close(self) -> None:
        with self._lock:
            self.source.close()
            self.ok = False

    def replace(self, source: FrameSource) -> None:
        """Look through `source` from now on (another camera chosen in Settings)."""
        with self._lock:
            self.source.close()
            self.source = source
            self.bus.forget("camera")
            self._open()

    def grab(self, t: float) -> np.ndarray | None:
        """A frame, reopening the camera if it failed a while ago; None if there is none."""
        with self._lock:
            if not self.ok:
                if t < self._retry_at:
                    return None
                self._open()
                if not self.ok:
                    return None
            try:
                frame = self.source.read()
            except ServantError as error:
                self._fault(error)
                return None
            self.bus.report("camera", True, f"{self.source.name}: ready")
            return frame

    def _open(self) -> None:
        try:
            self.source.open()
        except ServantError as error:
            self._fault(error)
            return
        self.ok = True
        self.bus.report("camera", True, f"{self.source.name}: ready")

    def _fault(self, error: ServantError) -> None:
        self.source.close()
        self.ok = False
        self._retry_at = self.bus.clock() + self.reopen_seconds
        self.bus.report("camera", False, str(error))


class Feeling:
    """A sample sense's source (motion, ambient readings), cut into windows like the sound.

    `on_window(sense, window, rate)` is called on the sense thread for each `window_seconds` of
    readings; a `SensorFrame` of the newest readings goes out at most `FRAMES_PER_SECOND` times a
    second for a live trace. The last `RING_SECONDS` are kept so teach mode can record them.
    """

    FRAMES_PER_SECOND = 5.0

    def __init__(
        self,
        sense: Sense,
        source: SampleSource,
        bus: EventBus,
        on_window: Callable[[str, np.ndarray, int], None],
        *,
        window_seconds: float,
        reopen_seconds: float,
    ) -> None:
        self.sense = sense
        self.source = source
        self.bus = bus
        self.on_window = on_window
        self.window_seconds = window_seconds
        self.reopen_seconds = reopen_seconds
        self.ok = False
        self._rows: list[np.ndarray] = []  # blocks not yet cut into a window
        self._rows_have = 0  # how many readings they hold
        self._kept: deque[np.ndarray] = deque()  # the last RING_SECONDS of blocks, for recording
        self._kept_rows = 0
        self._arrived = threading.Condition()
        self._total = 0
        self._retry_at = 0.0
        self._frame_at = -1.0
        self._watch: StreamWatch | None = None  # a live source's health, from its opening
        self._junk_at_open = 0

    @property
    def device(self) -> str:
        return self.sense.device

    def open(self) -> None:
        try:
            self.source.open()
        except ServantError as error:
            self.ok = False
            self._retry_at = self.bus.clock() + self.reopen_seconds
            self.bus.report(self.device, False, str(error))
            return
        self._rows = []  # windows start afresh after (re)opening, as the sound's do
        self._rows_have = 0
        self.ok = True
        self.bus.report(self.device, True, f"{self.source.name}: reading at {self.source.rate} Hz")
        if self.source.live:  # a board: watched for stalls and its rate
            self._watch = StreamWatch(self.source.name, self.source.rate, self.bus.clock())
            self._junk_at_open = self._junk()

    def _junk(self) -> int:
        return int(self.source.bad_lines)

    def _said(self, news: News | None) -> None:
        if news is not None:
            self.bus.report(self.device, news.ok, news.message)

    def close(self) -> None:
        self.source.close()
        with self._arrived:  # a recording waiting for readings learns at once that none come
            self.ok = False
            self._arrived.notify_all()

    def reopen_if_due(self, t: float) -> None:
        if not self.ok and t >= self._retry_at:
            self.open()

    @property
    def finished(self) -> bool:
        return self.source.exhausted

    def feel(self, timeout: float) -> None:
        """Take what readings came within `timeout` (0: only those already there)."""
        if not self.ok:
            self.reopen_if_due(self.bus.clock())
            return
        try:
            block = self.source.read(timeout)
        except ServantError as error:
            if not self.source.live:
                self.bus.error(str(error))
                return
            self.bus.report(self.device, False, str(error))
            self.close()
            self._retry_at = self.bus.clock() + self.reopen_seconds
            return
        watch = self._watch
        if block is None or not len(block):
            if self.source.exhausted:
                self.bus.report(self.device, False, f"{self.source.name}: finished")
            elif watch is not None:
                self._said(watch.quiet(self.bus.clock(), self._junk() - self._junk_at_open))
            return
        if watch is not None:
            self._said(watch.arrived(self.bus.clock(), len(block)))
            if not watch.usable:  # readings at another rate than the windows are cut by
                return
        block = np.asarray(block, dtype=np.float32).reshape(len(block), -1)
        self._keep(block)
        t = self.bus.clock()
        if t - self._frame_at >= 1.0 / self.FRAMES_PER_SECOND:
            self._frame_at = t
            recent = np.concatenate(self._kept)[-int(self.source.rate * 10) :]
            channels = tuple(self.source.channels)
            self.bus.emit(SensorFrame(t, self.sense.name, channels, recent, self.source.rate))
        self._rows.append(block)
        self._rows_have += len(block)
        size = int(round(self.window_seconds * self.source.rate))
        while self._rows_have >= size:
            rows = np.concatenate(self._rows)
            window, rest = rows[:size], rows[size:]
            self._rows = [rest] if len(rest) else []
            self._rows_have = len(rest)
            self.on_window(self.sense.name, window, self.source.rate)

    def _keep(self, block: np.ndarray) -> None:
        with self._arrived:
            self._kept.append(block)
            self._kept_rows += len(block)
            self._total += len(block)
            limit = int(RING_SECONDS * self.source.rate)
            while self._kept_rows - len(self._kept[0]) >= limit:
                self._kept_rows -= len(self._kept.popleft())
            self._arrived.notify_all()

    def record(
        self, seconds: float, timeout: float | None, cancel: threading.Event | None = None
    ) -> np.ndarray:
        """The next `seconds` of readings from now (blocks until they have arrived, `cancel` is
        set, or the source closes)."""
        if not self.ok:
            raise ServantError(f"{self.device}: no readings to record; check it (see status)")
        count = int(round(seconds * self.source.rate))
        with self._arrived:
            end = self._total + count
            deadline = time.monotonic() + (timeout if timeout is not None else 2 * seconds + 2)
            while not self._arrived.wait_for(
                lambda: self._total >= end or not self.ok, STOP_CHECK_SECONDS
            ):
                if cancel is not None and cancel.is_set():
                    raise ServantError(stopped_text(seconds))
                if time.monotonic() >= deadline:
                    break
            if self._total < end:
                raise ServantError(f"{self.source.name}: the readings stopped; try again")
            rows = np.concatenate(self._kept)
            start = len(rows) - (self._total - end) - count
            return rows[start : start + count].copy()
