"""The engine's senses as devices, together: the hearing (audio), the sight (camera) and a
feeling a sample sense (`loop`); opened and closed together, stepped on the sense thread,
recorded from on demand, and a device changed in Settings swapped in.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from servant_core.audio import SILENT_DBFS, is_silent
from servant_core.capture.source import AudioSource, FrameSource, ManualClock, SampleSource
from servant_core.engine.bus import EventBus
from servant_core.engine.loop import DeviceMakers, Feeling, Hearing, Sight
from servant_core.errors import ServantError
from servant_core.senses import SAMPLE_SENSES


class SenseDevices:
    """`audio`, `camera` (None: absent) and `samples` ({sample sense: source}) with the handles
    the sense thread works them through. `on_window(window, rate)` judges a sound window,
    `on_samples(sense, window, rate)` a sample sense's window."""

    def __init__(
        self,
        audio: AudioSource | None,
        camera: FrameSource | None,
        samples: Mapping[str, SampleSource],
        bus: EventBus,
        *,
        on_window: Callable[[np.ndarray, int], None],
        on_samples: Callable[[str, np.ndarray, int], None],
        window_seconds: float,
        reopen_seconds: float,
        spectrum_fps: float,
        spectrum_size: int,
    ) -> None:
        self._bus = bus
        self._clock = bus.clock
        self.hearing = (
            Hearing(
                audio,
                bus,
                on_window,
                window_seconds=window_seconds,
                reopen_seconds=reopen_seconds,
                spectrum_fps=spectrum_fps,
                spectrum_size=spectrum_size,
            )
            if audio is not None
            else None
        )
        self.sight = Sight(camera, bus, reopen_seconds=reopen_seconds) if camera else None
        self.feelings = [
            Feeling(
                SAMPLE_SENSES[sense],
                source,
                bus,
                on_samples,
                window_seconds=window_seconds,
                reopen_seconds=reopen_seconds,
            )
            for sense, source in samples.items()
        ]
        self._lock = threading.Lock()
        self._next_audio: AudioSource | None = None  # swapped in on the sense thread

    def open(self) -> None:
        for device in self._all():
            device.open()

    def close(self) -> None:
        for device in self._all():
            device.close()

    def _all(self) -> list[Hearing | Sight | Feeling]:
        """The senses in use: the hearing, the sight, then each feeling."""
        return [d for d in (self.hearing, self.sight) if d is not None] + list(self.feelings)

    def step(self, timeout: float, stop: threading.Event) -> bool:
        """One turn of the sense thread: take an audio block if one comes within `timeout`, then
        the readings of the sample senses; without working audio, the first sample sense waits
        (or `stop`, for `timeout`). False once the input has run out (a replay played out)."""
        hearing = self.hearing
        with self._lock:
            next_audio, self._next_audio = self._next_audio, None
        if next_audio is not None and hearing is not None:
            hearing.replace(next_audio)
        waited = False
        if hearing is not None and hearing.ok:
            if not hearing.listen(timeout):
                return False
            waited = True
        for feeling in self.feelings:
            feeling.feel(0.0 if waited else timeout)
            waited = waited or feeling.ok
        if not waited:
            if isinstance(self._clock, ManualClock) and not self.feelings:
                # Nothing moves a manual clock but a replay: without one there is no time.
                return False
            stop.wait(timeout)
            if hearing is not None:
                hearing.reopen_if_due(self._clock())
        return not (hearing is None and self.feelings and all(f.finished for f in self.feelings))

    def use(self, before: Any, settings: Any, makers: DeviceMakers) -> None:
        """Open the camera or microphone that changed from `before` to `settings` (Settings)."""
        if settings.camera != before.camera and self.sight is not None:
            self.sight.replace(makers.camera(settings.camera))
        if settings.audio_device != before.audio_device and self.hearing is not None:
            with self._lock:
                self._next_audio = makers.microphone(settings.audio_device)

    @property
    def audio_rate(self) -> int:
        return self.hearing.rate if self.hearing is not None else 0

    def record_window(
        self, seconds: float, timeout: float | None, cancel: threading.Event | None
    ) -> np.ndarray:
        """`Engine.record_window`, the engine running."""
        if self.hearing is None:
            raise ServantError("microphone: no sound to record; check the microphone (see status)")
        window = self.hearing.record(seconds, timeout, cancel)
        if is_silent(window):  # a place taught as silence would be named wherever it is quiet
            raise ServantError(
                f"microphone: the recording is silence (below {SILENT_DBFS:.0f} dBFS) and was not "
                "kept; unmute or check the microphone, then record again"
            )
        return window

    def record_samples(
        self, sense: str, seconds: float, timeout: float | None, cancel: threading.Event | None
    ) -> tuple[np.ndarray, int]:
        """`Engine.record_samples`, the engine running."""
        for feeling in self.feelings:
            if feeling.sense.name == sense:
                return feeling.record(seconds, timeout, cancel), feeling.source.rate
        raise ServantError(f"{sense}: not in use; start with its sensor (e.g. --imu PORT)")

    def take_picture(self) -> np.ndarray:
        """`Engine.take_picture`."""
        if self.sight is None:
            raise ServantError("camera: none in use; start with a camera to take pictures")
        frame = self.sight.grab(self._clock())
        if frame is None:
            message = self._bus.status.get("camera")
            raise ServantError(message.message if message else "camera: no picture")
        return frame
