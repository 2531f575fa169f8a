"""The microphone, through sounddevice (PortAudio).

PortAudio runs the stream callback on its own thread, so the callback only copies the block onto a
bounded queue and counts what it had to drop; everything else (windows, spectra, predictions)
happens on the engine's thread. sounddevice is imported lazily: it raises OSError at import when
libportaudio is missing, and `import servant_core` must never fail for want of a sound card.
"""

from __future__ import annotations

import queue
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import numpy as np

from servant_core.errors import ServantError

DEFAULT_BLOCK_SECONDS = 0.02
DEFAULT_QUEUE_SECONDS = 10.0


def load_sounddevice() -> ModuleType:
    """Import sounddevice, or say in one line that PortAudio is missing and how to get it."""
    try:
        import sounddevice
    except OSError as exc:
        raise ServantError(
            f"microphone: the PortAudio library is missing ({exc}); install it "
            "(Debian: apt-get install libportaudio2) — running without sound"
        ) from exc
    return sounddevice


def rescan_devices(sd: ModuleType) -> bool:
    """Start PortAudio again, so that its device list is the one there is now (it closes any
    stream open); False if it could not."""
    try:
        sd._terminate()
        sd._initialize()
    except Exception:  # PortAudio's errors are generic; the caller's own error says what to do
        return False
    return True


@dataclass(frozen=True)
class InputDevice:
    index: int
    name: str
    channels: int
    default_rate: int
    is_default: bool


def list_input_devices() -> list[InputDevice]:
    """Every device that can record, with its default rate; ServantError without PortAudio."""
    sd = load_sounddevice()
    try:
        devices = sd.query_devices()
        default_in = sd.default.device[0]
    except Exception as exc:  # PortAudio reports host-API failures as generic errors
        raise ServantError(f"microphone: cannot list sound devices ({exc})") from exc
    return [
        InputDevice(
            i,
            d["name"],
            int(d["max_input_channels"]),
            int(d["default_samplerate"]),
            i == default_in,
        )
        for i, d in enumerate(devices)
        if d["max_input_channels"] > 0
    ]


def find_input_device(device: int | str | None) -> InputDevice:
    """The input device by index, by (part of its) name, or the default one when None."""
    devices = list_input_devices()
    if not devices:
        raise ServantError("microphone: no input device found; plug one in or use `servant demo`")
    if device is None:
        return next((d for d in devices if d.is_default), devices[0])
    if isinstance(device, int) or (isinstance(device, str) and device.isdigit()):
        match = [d for d in devices if d.index == int(device)]
    else:
        match = [d for d in devices if d.name == device] or [
            d for d in devices if device.lower() in d.name.lower()
        ]
    if not match:
        names = ", ".join(f"{d.index}: {d.name}" for d in devices)
        raise ServantError(f"microphone {device!r}: no such input device; choose one of {names}")
    return match[0]


class Microphone:
    """A live input stream, mono, at the device's default rate unless `rate` is given.

    If the device refuses `rate`, the stream opens at the device's default rate instead and
    `rate_note` says so (the engine reports it once). `overflows` counts blocks dropped because the
    queue was full plus blocks PortAudio flagged as overflowed.
    """

    def __init__(
        self,
        device: int | str | None = None,
        rate: int | None = None,
        block_seconds: float = DEFAULT_BLOCK_SECONDS,
        queue_seconds: float = DEFAULT_QUEUE_SECONDS,
    ) -> None:
        self.device = device
        self.requested_rate = rate
        self.block_seconds = block_seconds
        self.queue_seconds = queue_seconds
        self.name = f"microphone {device!r}" if device is not None else "microphone"
        self.live = True
        self.rate = rate or 0
        self.rate_note: str | None = None
        self.overflows = 0
        self._queue: queue.Queue[np.ndarray] = queue.Queue()
        self._stream: Any = None

    def open(self) -> None:
        sd = load_sounddevice()
        try:
            self._open(sd, find_input_device(self.device))
        except ServantError:
            # PortAudio knows the devices there were when it started: a microphone plugged in
            # since, or back after a fault under another number, is found only once it starts
            # again (the way sounddevice's maintainers give). Servant has no other stream open
            # meanwhile (this one is closed), so nothing else stops.
            if not rescan_devices(sd):
                raise
            self._open(sd, find_input_device(self.device))

    def _open(self, sd: ModuleType, info: InputDevice) -> None:
        self.name = f"microphone {info.name!r}"
        rate = self.requested_rate or info.default_rate
        try:
            sd.check_input_settings(device=info.index, channels=1, samplerate=rate, dtype="float32")
        except Exception as exc:
            if rate == info.default_rate:
                raise ServantError(f"{self.name}: cannot record mono at {rate} Hz ({exc})") from exc
            self.rate_note = (
                f"{self.name}: refuses {rate} Hz ({exc}); recording at its default "
                f"{info.default_rate} Hz instead"
            )
            rate = info.default_rate
        self.rate = int(rate)
        blocksize = max(1, int(round(self.rate * self.block_seconds)))
        self._queue = queue.Queue(maxsize=max(4, int(self.queue_seconds / self.block_seconds)))
        try:
            self._stream = sd.InputStream(
                device=info.index,
                channels=1,
                samplerate=self.rate,
                blocksize=blocksize,
                dtype="float32",
                callback=self._callback,
            )
            self._stream.start()
        except Exception as exc:
            self.close()
            raise ServantError(f"{self.name}: cannot open the input stream ({exc})") from exc

    def _callback(self, indata: np.ndarray, frames: int, time: Any, status: Any) -> None:
        # PortAudio's thread: copy and enqueue, nothing that blocks, allocates much, or raises.
        if status.input_overflow:
            self.overflows += 1
        try:
            self._queue.put_nowait(indata[:, 0].copy())
        except queue.Full:
            self.overflows += 1

    def read(self, timeout: float) -> np.ndarray | None:
        """Every block queued since the last read, as one (waiting up to `timeout` for the
        first). A sense thread held up by a busy machine or a garbage collection catches up in
        one turn rather than one turn per 20 ms block, which it might never do: the queue would
        fill and the sound be lost, and a 5 s recording take longer than 5 s to arrive."""
        try:
            blocks = [self._queue.get(timeout=timeout)]
        except queue.Empty:
            blocks = []
        while blocks:
            try:
                blocks.append(self._queue.get_nowait())
            except queue.Empty:
                return blocks[0] if len(blocks) == 1 else np.concatenate(blocks)
        if self._stream is None or not self._stream.active:
            raise ServantError(
                f"{self.name}: the input stream stopped (device unplugged?); reconnect it"
            )
        return None

    @property
    def exhausted(self) -> bool:
        return False

    def close(self) -> None:
        stream, self._stream = self._stream, None
        if stream is not None:
            try:
                stream.abort()
                stream.close()
            except Exception:  # a device already gone cannot be closed twice; nothing to keep
                pass
