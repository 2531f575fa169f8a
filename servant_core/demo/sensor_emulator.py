"""The sensor board in software: synthesised motion and ambient lines on one side of a pty pair.

It streams what `docs/sensor_board.ino` streams (the line format of `capture.sensors`), at the
board's rates, by its own clock: the motion and ambient values of the scene a script says the
wearer is in (`demo.motion_synth`), five-second stretch by five-second stretch, seeded. The
host opens the pty's other side with pyserial exactly as it would open the Arduino's USB port;
`stop()` closes the pty, which to the host is the cable pulled.
"""

from __future__ import annotations

import os
import threading
import time
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from servant_core.audio import DEFAULT_WINDOW_SECONDS
from servant_core.capture.sensors import AMBIENT_RATE, IMU_RATE, format_line
from servant_core.demo.motion_synth import SEA_LEVEL_HPA, synth_ambient, synth_motion
from servant_core.errors import ServantError
from servant_core.pty_port import PtyPort, PtyService

CHUNK_SECONDS = DEFAULT_WINDOW_SECONDS  # synthesised a window at a time, like the demo's sound
TICK_S = 0.02
SENSOR_STREAM = 3  # the seed word of the sensors' randomness (the demo uses 1 and 2)
BANNER = b"# servant sensor board emulator: I,ms,ax,ay,az,gx,gy,gz / A,ms,lux,celsius,hpa\n"


def parse_script(text: str) -> list[tuple[str, float]]:
    """`coffee:20,gym:20,street:55` as (scene, seconds) pairs; a bare scene lasts forever."""
    script = []
    for part in [p.strip() for p in text.split(",") if p.strip()]:
        scene, _, seconds = part.partition(":")
        try:
            length = float(seconds) if seconds else float("inf")
        except ValueError:
            length = float("nan")
        if not scene or not length > 0:
            raise ServantError(
                f"{part!r} is not scene:seconds; write e.g. coffee:20,gym:20,street:55"
            )
        script.append((scene.strip(), length))
    if not script:
        raise ServantError("the scene script is empty; write e.g. coffee:20,gym:20,street:55")
    return script


def script_scene(script: Sequence[tuple[str, float]]) -> Callable[[float], str]:
    """The scene at stream time t of a script played over and over."""
    total = sum(seconds for _, seconds in script)

    def scene_at(t: float) -> str:
        t = t % total if np.isfinite(total) else t
        for scene, seconds in script:
            if t < seconds:
                return scene
            t -= seconds
        return script[-1][0]

    return scene_at


class SensorEmulator(PtyService):
    """Streams the lines of `scene_at(t)` on a pty from `start()` on; `inject(data)` slips raw
    bytes (a bad line) into the stream. `lines_between(t0, t1)` is what it sends in that span."""

    def __init__(
        self,
        scene_at: Callable[[float], str],
        *,
        seed: int = 0,
        imu_rate: int = IMU_RATE,
        ambient_rate: int = AMBIENT_RATE,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self.scene_at = scene_at
        self.seed = seed
        self.rates = {"imu": imu_rate, "ambient": ambient_rate}
        self.clock = clock
        self.dropped_bytes = 0  # what the host did not read in time (a full pty buffer)
        self.port: str | None = None
        self._chunks: dict[tuple[str, int], np.ndarray] = {}
        self._sent = {"imu": 0, "ambient": 0}
        self._injected: list[bytes] = []
        self._lock = threading.Lock()
        self._t0 = 0.0

    def _chunk(self, kind: str, k: int) -> np.ndarray:
        """The k-th five-second stretch of a stream (the latest two kept)."""
        key = (kind, k)
        if key not in self._chunks:
            scene = self.scene_at(k * CHUNK_SECONDS)
            rng = np.random.default_rng([self.seed, SENSOR_STREAM, int(kind == "ambient"), k])
            if kind == "imu":
                chunk = synth_motion(scene, rng, CHUNK_SECONDS, self.rates[kind])
            else:
                # the weather drifts by a couple of hPa over an hour
                weather = SEA_LEVEL_HPA + 2.0 * np.sin(2 * np.pi * k * CHUNK_SECONDS / 3600)
                # where the wearer stands in a place: the same for every stretch of the place
                place = np.random.default_rng(
                    [self.seed, SENSOR_STREAM, 2, zlib.crc32(scene.encode())]
                )
                chunk = synth_ambient(scene, rng, CHUNK_SECONDS, self.rates[kind], weather, place)
            self._chunks = {k2: v for k2, v in self._chunks.items() if k2[1] >= k - 1}
            self._chunks[key] = chunk
        return self._chunks[key]

    def _lines(self, kind: str, first: int, stop: int) -> list[tuple[float, bytes]]:
        rate = self.rates[kind]
        per_chunk = int(round(CHUNK_SECONDS * rate))
        out = []
        for i in range(first, stop):
            row = self._chunk(kind, i // per_chunk)[i % per_chunk]
            out.append((i / rate, format_line(kind, int(i * 1000 / rate), row)))
        return out

    def lines_between(self, start: float, end: float) -> bytes:
        """The lines of readings taken in [start, end) seconds of stream time, in time order."""
        spans = [
            self._lines(kind, int(np.ceil(start * rate)), int(np.ceil(end * rate)))
            for kind, rate in self.rates.items()
        ]
        return b"".join(line for _, line in sorted(spans[0] + spans[1], key=lambda x: x[0]))

    def inject(self, data: bytes) -> None:
        with self._lock:
            self._injected.append(data)

    def start(self, link: str | Path | None = None) -> str:
        """Serve on a new pty; return the port to open (`link`, a symlink to it, if given)."""
        self._pty = PtyPort(link)
        os.set_blocking(self._pty.master, False)  # a host that does not read must not stall it
        self.port = self._pty.device
        self._t0 = self.clock()
        self._sent = {"imu": 0, "ambient": 0}
        self._stop.clear()
        self._write(BANNER)
        self._thread = threading.Thread(target=self._serve, name="sensor-emulator", daemon=True)
        self._thread.start()
        return self._pty.port

    def _write(self, data: bytes) -> None:
        assert self._pty is not None
        try:
            written = os.write(self._pty.master, data)
        except BlockingIOError:
            written = 0
        self.dropped_bytes += len(data) - written

    def _serve(self) -> None:
        while not self._stop.wait(TICK_S):
            now = self.clock() - self._t0
            with self._lock:
                injected, self._injected = self._injected, []
            lines = []
            for kind, rate in self.rates.items():
                due = int(now * rate) + 1
                lines += self._lines(kind, self._sent[kind], due)
                self._sent[kind] = max(self._sent[kind], due)
            data = b"".join(injected) + b"".join(line for _, line in sorted(lines))
            if data:
                try:
                    self._write(data)
                except OSError:
                    return
