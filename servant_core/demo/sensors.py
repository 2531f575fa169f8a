"""The demo's motion and ambient senses: the wearer sits in the café, bounces on the court and
walks down the street (`demo.motion_synth`), with each place's light, warmth and pressure.

At real speed they come from the sensor board's emulator on a pty, read through pyserial exactly
as a real board would be (`demo.sensor_emulator`, `capture.sensors`); as fast as possible (a
`ManualClock`), from the same synthesis window by window, following the sound's clock. The motion
follows where the wearer *is* — the scene heard — even while the camera still shows the café.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Iterator

import numpy as np

from servant_core.audio import DEFAULT_WINDOW_SECONDS
from servant_core.capture.replay import Clip
from servant_core.capture.sample_files import PacedSamples
from servant_core.capture.sensors import CHANNELS, RATES, SensorBoard
from servant_core.capture.source import ManualClock, SampleSource
from servant_core.demo.motion_synth import DEMO_SCENES, synth_ambient, synth_motion
from servant_core.demo.scenes import FAST_BLOCK_SECONDS, WALK, Segment, segment_at
from servant_core.demo.sensor_emulator import SENSOR_STREAM, SensorEmulator, script_scene
from servant_core.recognisers import FRESH_METHODS, Recogniser, make_recogniser

TRAIN_STREAM = 7  # the seed word of the sensors' training windows: never the walk's
SYNTH: dict[str, Callable[..., np.ndarray]] = {"motion": synth_motion, "ambient": synth_ambient}
STREAM = {"motion": "imu", "ambient": "ambient"}


def train_sensor_recognisers(seed: int = 0, windows_per_scene: int = 12) -> dict[str, Recogniser]:
    """The motion and ambient recognisers of the demo, fitted on fresh synthesised windows."""
    fitted: dict[str, Recogniser] = {}
    for k, (sense, synth) in enumerate(SYNTH.items()):
        windows, scenes = [], []
        for s, scene in enumerate(DEMO_SCENES):
            for i in range(windows_per_scene):
                windows.append(synth(scene, np.random.default_rng([seed, TRAIN_STREAM, k, s, i])))
                scenes.append(scene)
        model = make_recogniser(sense, FRESH_METHODS[sense], random_state=seed)
        fitted[sense] = model.fit(model.featurize(windows), scenes)
    return fitted


def walk_script(walk: tuple[Segment, ...] = WALK) -> list[tuple[str, float]]:
    """The walk as the emulator's script: where the wearer is (the scene heard), for how long."""
    return [(segment.sound, segment.seconds) for segment in walk]


def _walk_clips(sense: str, seed: int) -> Iterator[Clip]:
    for k in itertools.count():
        scene = segment_at(k * DEFAULT_WINDOW_SECONDS).sound
        rng = np.random.default_rng([seed, SENSOR_STREAM, len(sense), k])
        yield Clip(scene, SYNTH[sense](scene, rng))


def demo_sensor_sources(
    seed: int = 0, *, clock: ManualClock | None = None
) -> tuple[dict[str, SampleSource], Callable[[], None] | None]:
    """({sense: source} of the walk, and what stops the emulator — None without one).

    With `clock` (a fast run) the sources follow it; without, the emulator streams the walk at
    real speed on a pty and a `SensorBoard` reads both streams from it."""
    if clock is not None:
        sources: dict[str, SampleSource] = {
            sense: PacedSamples(
                _walk_clips(sense, seed),
                RATES[STREAM[sense]],
                CHANNELS[STREAM[sense]],
                follow=clock,
                realtime=False,
                block_seconds=FAST_BLOCK_SECONDS,  # a block for each of the sound's
                name=f"demo {sense}",
            )
            for sense in SYNTH
        }
        return sources, None
    board = DemoBoard(seed)
    return {sense: board.source(STREAM[sense]) for sense in SYNTH}, board.stop


class DemoBoard:
    """The emulated sensor board, started when the engine first opens one of its streams: the
    walk's sound and pictures start then too, so the wearer moves with what is heard and seen
    (started earlier, it ran ahead by the demo's training and start-up time)."""

    def __init__(self, seed: int) -> None:
        self.emulator = SensorEmulator(script_scene(walk_script()), seed=seed)
        self.board: SensorBoard | None = None
        self._lock = threading.Lock()

    def source(self, stream: str) -> DemoStream:
        return DemoStream(self, stream)

    def started(self) -> SensorBoard:
        with self._lock:
            if self.board is None:
                self.board = SensorBoard(self.emulator.start())
            return self.board

    def stop(self) -> None:
        self.emulator.stop()


class DemoStream:
    """One stream of the `DemoBoard`, as a `SampleSource` (a real `SerialSamples` once open)."""

    def __init__(self, board: DemoBoard, stream: str) -> None:
        self.demo_board = board
        self.stream = stream
        self.name = f"demo {stream} sensor"
        self.rate = RATES[stream]
        self.channels = CHANNELS[stream]
        self.live = True
        self.bad_lines = 0  # the emulator's lines are readings: none counted
        self._serial: SampleSource | None = None

    def open(self) -> None:
        self._serial = self.demo_board.started().source(self.stream)
        self._serial.open()
        self.name = self._serial.name

    def read(self, timeout: float) -> np.ndarray | None:
        return self._serial.read(timeout) if self._serial is not None else None

    @property
    def exhausted(self) -> bool:
        return False

    def close(self) -> None:
        if self._serial is not None:
            self._serial.close()
