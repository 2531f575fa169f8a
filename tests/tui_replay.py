"""A finite, deterministic replay of engine events, for the TUI's snapshot and Pilot tests.

Why a replay and not the real engine here: a snapshot must show the same pixels every run, so the
events come from a fixed script with fixed times (no wall clock, no threads racing). It speaks the
same API as `servant_core.engine.Engine` and emits the real event types of `servant_core.events`.
The tests over the real demo engine live beside these (`test_tui_demo_engine.py`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from servant_core.errors import ServantError
from servant_core.events import (
    AcousticPrediction,
    ArmState,
    Decision,
    DeviceStatus,
    FusionState,
    Palette,
    SensePrediction,
    SensorFrame,
    SpectrumFrame,
    UnknownScene,
    VisualPrediction,
)
from servant_core.senses import SAMPLE_SENSES

RATE = 44100
JOINTS = {"shoulder": 90.0, "elbow": 45.0, "wrist": 120.0}


def spectrum_frame(t: float, seed: int = 0) -> SpectrumFrame:
    """A pink-ish noise spectrum with two hums, the same for the same seed."""
    rng = np.random.default_rng(seed)
    freqs = np.fft.rfftfreq(4096, 1 / RATE)[1:]
    level = -30.0 - 10.0 * np.log10(freqs / 100.0 + 1.0) * 2.0 + rng.normal(0, 3, len(freqs))
    for hum in (120.0, 2400.0):
        level += 25.0 * np.exp(-(((freqs - hum) / (hum * 0.04)) ** 2))
    return SpectrumFrame(t=t, freqs=freqs, magnitude_db=np.clip(level, -100, 0))


COFFEE = np.array([[92, 58, 38], [201, 170, 130], [30, 28, 26], [240, 236, 226]], dtype=np.uint8)
COFFEE_TRAINED = np.array(
    [[98, 60, 40], [196, 166, 128], [34, 30, 28], [236, 232, 222]], dtype=np.uint8
)


def demo_script() -> list[Any]:
    """A short afternoon: no scene at first, then a coffee shop confirmed by two pictures; the
    recognisers give probabilities in percent (as `codebook` and `bovw` do)."""
    return [
        DeviceStatus(0.0, "microphone", True, "demo synth 44.1 kHz"),
        DeviceStatus(0.0, "camera", True, "demo frames"),
        DeviceStatus(0.0, "servo", True, "emulator on /dev/pts/3"),
        ArmState(0.0, True, False, "maestro", "/dev/pts/3", dict(JOINTS)),
        AcousticPrediction(5.0, "GymScene", 61.4, {"GymScene": 0.6, "CoffeeScene": 0.4}, "%"),
        FusionState(5.0, "looking", "GymScene", 30.0, 0),
        FusionState(35.0, "listening", None, None, 0),
        Decision(35.0, None, 0.0, "No scene detected"),
        AcousticPrediction(40.0, "CoffeeScene", 91.2, {"CoffeeScene": 0.9, "GymScene": 0.1}, "%"),
        FusionState(40.0, "looking", "CoffeeScene", 30.0, 0),
        Palette(44.0, COFFEE, np.array([0.41, 0.27, 0.2, 0.12]), "CoffeeScene", COFFEE_TRAINED),
        VisualPrediction(44.0, "CoffeeScene", 83.8, {"CoffeeScene": 0.8}, "%"),
        FusionState(44.0, "confirming", "CoffeeScene", 26.0, 1),
        FusionState(48.0, "confirming", "CoffeeScene", 22.0, 2),
        Decision(48.0, "CoffeeScene", 87.5, "CoffeeScene detected", 91.2, 83.8, "%"),
        ArmState(
            48.0,
            True,
            False,
            "maestro",
            "/dev/pts/3",
            dict(JOINTS),
            {"shoulder": 30.0, "elbow": 100.0, "wrist": 90.0},
        ),
        AcousticPrediction(53.0, "CoffeeScene", 88.0, {"CoffeeScene": 0.85}, "%"),
        FusionState(53.0, "looking", "CoffeeScene", 30.0, 0),
        FusionState(60.5, "looking", "CoffeeScene", 22.5, 1),
        spectrum_frame(60.5),
    ]


IMU_RATE = 50
AMBIENT_RATE = 2


def walking_frame(t: float, seconds: float = 10.0) -> SensorFrame:
    """The last `seconds` of an IMU worn while walking: gravity on z, a 2 Hz step bounce of
    ±4 m/s², a little sway and turning; the same for the same `t`."""
    n = int(seconds * IMU_RATE)
    times = t - seconds + np.arange(1, n + 1) / IMU_RATE
    step = np.sin(2 * np.pi * 2.0 * times)
    rows = np.column_stack(
        [
            0.8 * np.sin(2 * np.pi * 1.0 * times),
            0.3 * np.cos(2 * np.pi * 1.0 * times),
            9.81 + 4.0 * step,
            5.0 * step,
            2.0 * np.cos(2 * np.pi * 2.0 * times),
            1.0 + 0.0 * times,
        ]
    ).astype(np.float32)
    return SensorFrame(t, "motion", ("ax", "ay", "az", "gx", "gy", "gz"), rows, IMU_RATE)


def ambient_frame(t: float) -> SensorFrame:
    """A café's light, warmth and pressure over the last 10 s."""
    rows = np.tile(np.float32([[312.0, 21.5, 1013.2]]), (10 * AMBIENT_RATE, 1))
    return SensorFrame(t, "ambient", ("lux", "celsius", "hpa"), rows, AMBIENT_RATE)


def sensing_script() -> list[Any]:
    """The afternoon of `demo_script` worn with the sensor board: the motion and ambient senses
    judge each window too, and the last decision leaned on sound and motion."""
    return [
        *demo_script()[:4],
        DeviceStatus(0.0, "imu", True, "/dev/pts/4: reading at 50 Hz"),
        DeviceStatus(0.0, "ambient", True, "/dev/pts/4: reading at 2 Hz"),
        *demo_script()[4:-1],
        SensePrediction(53.0, "motion", "street", 77.0, {"street": 0.77, "coffee": 0.2}, "%"),
        SensePrediction(53.0, "ambient", "CoffeeScene", 91.0, {"CoffeeScene": 0.91}, "%"),
        Decision(
            58.0,
            "CoffeeScene",
            90.1,
            "CoffeeScene detected",
            88.0,
            0.0,
            "%",
            leaned_on=("audio", "motion"),
        ),
        ambient_frame(60.5),
        walking_frame(60.5),
        spectrum_frame(60.5),
    ]


class ReplayEngine:
    """Emits `script` on `start()`, in order, from the calling thread; records what it is asked."""

    retrain_reports_progress = False  # its `retrain` takes the library alone

    def __init__(
        self,
        script: list[Any] | None = None,
        *,
        window_source: np.ndarray | None = None,
        audio_rate: int = RATE,
    ) -> None:
        self.audio_rate = audio_rate
        self.script = demo_script() if script is None else script
        self.callbacks: list[Callable[[Any], None]] = []
        self.started = threading.Event()
        self.stopped = threading.Event()
        self.armed = False
        self.labels: list[tuple[str, str]] = []
        self.retrained: list[Any] = []
        self.window_source = window_source
        self.windows_recorded = 0
        self.pictures_taken = 0
        self.t = 0.0
        self._arm: ArmState | None = None
        # what the app reads of `servant_core.engine.Engine`: a replay keeps no library or model,
        # runs on no settings of its own and has no recognisers
        self.library_root: Path | None = None
        self.model_path: Path | None = None
        self.user_settings: Any = None
        self.acoustic: Any = None
        self.visual: Any = None
        self.settings_applied: list[Any] = []
        self.pose_for: Any = None

    @property
    def sample_senses(self) -> list[str]:
        """The sample senses of the script (as an engine knows its sources before it starts)."""
        said = {e.sense for e in self.script if isinstance(e, (SensePrediction, SensorFrame))}
        return [s for s in SAMPLE_SENSES if s in said]

    def subscribe(self, callback: Callable[[Any], None]) -> None:
        self.callbacks.append(callback)

    def emit(self, event: Any) -> None:
        if isinstance(event, ArmState):
            self._arm = event
        self.t = max(self.t, event.t)
        for callback in self.callbacks:
            callback(event)

    def start(self) -> None:
        for event in self.script:
            self.emit(event)
        self.started.set()

    def stop(self) -> None:
        self.stopped.set()

    def _set_armed(self, armed: bool) -> None:
        if self._arm is None or not self._arm.connected:
            raise ServantError("servo: not connected; check the serial port in Settings")
        self.armed = armed
        state = self._arm
        self.emit(
            ArmState(
                self.t, True, armed, state.protocol, state.port, dict(state.angles), state.target
            )
        )

    def arm(self) -> None:
        self._set_armed(True)

    def disarm(self) -> None:
        self._set_armed(False)

    def label_unknown(self, window_id: str, scene: str) -> None:
        self.labels.append((window_id, scene))

    def apply_settings(self, settings: Any) -> None:
        self.settings_applied.append(settings)

    def set_action_learner(self, pose_for: Any) -> None:
        self.pose_for = pose_for

    def read_arm_pose(self) -> dict[str, float]:
        raise ServantError("arm: this engine cannot read the arm's pose; type the angles")

    def record_samples(
        self,
        sense: str,
        seconds: float,
        timeout: float | None = None,
        cancel: threading.Event | None = None,
    ) -> tuple[np.ndarray, int]:
        raise ServantError(f"{sense}: no readings to record in this replay")

    def record_window(
        self, seconds: float, timeout: float | None = None, cancel: threading.Event | None = None
    ) -> np.ndarray:
        """The next `seconds` of the replayed source (a recording the test hands in)."""
        if self.window_source is None:
            raise ServantError("microphone: no audio source in this replay")
        n = int(seconds * self.audio_rate)
        start = (self.windows_recorded * n) % max(len(self.window_source) - n, 1)
        self.windows_recorded += 1
        self.emit(spectrum_frame(self.t, seed=self.windows_recorded))
        return self.window_source[start : start + n]

    def take_picture(self) -> np.ndarray:
        """A picture in the coffee shop's colours, the same every time for the same count."""
        rng = np.random.default_rng(self.pictures_taken)
        self.pictures_taken += 1
        picture = COFFEE[rng.integers(0, len(COFFEE), size=(48, 64))][..., ::-1]
        return np.ascontiguousarray(picture)

    def retrain(self, library: Any) -> None:
        self.retrained.append(library)


def unknown_scene_script() -> list[Any]:
    return demo_script() + [UnknownScene(61.0, "audio", "GymScene", "window-7")]
