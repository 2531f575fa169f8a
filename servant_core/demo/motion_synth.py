"""Synthesised motion (an MPU-6050 worn on the body) and ambient values for the demo's scenes.

Motion is (n, 6) at the sensor rate: acceleration in m/s² (gravity included, the body's
orientation drawn per window) and rotation in deg/s, for sitting (the coffee shop), walking (the
street), bouncing (the basketball gym) and vehicle (no demo scene yet). Ambient values are (n, 3):
lux, °C, hPa, each place with its own light and warmth, the pressure a weather level shared across
places. Everything is deterministic by the generator passed in.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from servant_core.audio import DEFAULT_WINDOW_SECONDS
from servant_core.capture.sample_files import SUFFIXES, write_sample_csv
from servant_core.capture.sensors import AMBIENT_RATE, IMU_RATE

G = 9.80665
MOTION_KINDS = ("sitting", "walking", "bouncing", "vehicle")
# what the wearer does in each demo scene
SCENE_MOTION = {"coffee": "sitting", "street": "walking", "gym": "bouncing", "vehicle": "vehicle"}
# (median lux, °C) of each demo scene: a café's warm light, a bright gym, daylight outside
SCENE_AMBIENT = {
    "coffee": (250.0, 22.5),
    "gym": (600.0, 18.5),
    "street": (8000.0, 12.0),
    "vehicle": (1500.0, 20.0),
}
SEA_LEVEL_HPA = 1013.25
DEMO_SCENES = ("coffee", "gym", "street")  # as `demo.scenes.SCENES` (not imported: it loads cv2)
LIBRARY_STREAM = 4  # the seed word of `write_sensor_library`'s windows


def _orientation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix: the sensor tilted up to ~35° from level, at any heading."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    angle = rng.uniform(0, 0.6)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _smooth_noise(rng: np.random.Generator, n: int, rate: int, cutoff: float) -> np.ndarray:
    """(n, 3) noise low-passed below `cutoff` Hz (a moving average), unit variance."""
    width = max(1, int(rate / max(cutoff, 1e-3)))
    raw = rng.normal(size=(n + width, 3))
    kernel = np.ones(width) / width
    out = np.stack([np.convolve(raw[:, c], kernel, mode="valid")[:n] for c in range(3)], axis=1)
    return out / max(float(out.std()), 1e-9)


def _sitting(rng: np.random.Generator, t: np.ndarray, rate: int) -> tuple[np.ndarray, np.ndarray]:
    acc = 0.03 * rng.normal(size=(len(t), 3))
    gyro = 0.3 * rng.normal(size=(len(t), 3))
    for _ in range(rng.poisson(1.0)):  # a hand lifting the cup, about once per window
        centre, width = rng.uniform(t[0], t[-1]), rng.uniform(0.4, 1.2)
        bump = np.exp(-0.5 * ((t - centre) / (width / 3)) ** 2)[:, None]
        acc += bump * rng.normal(0, 0.6, 3)
        gyro += bump * rng.normal(0, 20.0, 3)
    return acc, gyro


def _walking(rng: np.random.Generator, t: np.ndarray, rate: int) -> tuple[np.ndarray, np.ndarray]:
    f = rng.uniform(1.6, 2.0)
    phase = rng.uniform(0, 2 * np.pi)
    amp = rng.uniform(1.8, 3.0)
    step = 2 * np.pi * f * t + phase
    acc = np.zeros((len(t), 3))
    acc[:, 2] = amp * np.sin(step) + 0.35 * amp * np.sin(2 * step + 0.7)
    acc[:, 0] = 0.5 * amp * np.sin(step / 2)  # the side to side sway, one per stride
    acc[:, 1] = 0.4 * amp * np.sin(step + 1.2)
    acc += 0.25 * _smooth_noise(rng, len(t), rate, 6.0)
    gyro = np.stack(
        [25 * np.sin(step / 2), 12 * np.sin(step + 0.4), 18 * np.sin(step / 2 + 1.0)], axis=1
    )
    return acc, gyro + 3.0 * rng.normal(size=gyro.shape)


def _bouncing(rng: np.random.Generator, t: np.ndarray, rate: int) -> tuple[np.ndarray, np.ndarray]:
    f = rng.uniform(2.2, 3.0)
    step = 2 * np.pi * f * t + rng.uniform(0, 2 * np.pi)
    amp = rng.uniform(6.0, 10.0)
    landing = np.abs(np.sin(step / 2)) ** 6  # a sharp peak once a period
    acc = np.zeros((len(t), 3))
    acc[:, 2] = amp * (landing - landing.mean()) * 3.0
    acc[:, :2] = 1.5 * _smooth_noise(rng, len(t), rate, 3.0)[:, :2]
    gyro = 70.0 * _smooth_noise(rng, len(t), rate, 2.5) + 30 * np.sin(step)[:, None]
    return acc + 0.5 * rng.normal(size=acc.shape), gyro


def _vehicle(rng: np.random.Generator, t: np.ndarray, rate: int) -> tuple[np.ndarray, np.ndarray]:
    vibration = np.zeros((len(t), 3))
    for _ in range(3):  # engine and road: a few partials between 10 and 18 Hz
        f = rng.uniform(10.0, min(18.0, 0.45 * rate))
        vibration += (
            rng.uniform(0.1, 0.3, 3) * np.sin(2 * np.pi * f * t + rng.uniform(0, 6, 3)[:, None]).T
        )
    sway = 0.6 * _smooth_noise(rng, len(t), rate, 0.3)
    acc = vibration + sway + 0.05 * rng.normal(size=vibration.shape)
    gyro = 4.0 * _smooth_noise(rng, len(t), rate, 0.3) + 1.0 * rng.normal(size=vibration.shape)
    return acc, gyro


MOTIONS: dict[
    str, Callable[[np.random.Generator, np.ndarray, int], tuple[np.ndarray, np.ndarray]]
] = {"sitting": _sitting, "walking": _walking, "bouncing": _bouncing, "vehicle": _vehicle}


def synth_motion(
    kind: str,
    rng: np.random.Generator,
    seconds: float = DEFAULT_WINDOW_SECONDS,
    rate: int = IMU_RATE,
) -> np.ndarray:
    """(n, 6) float32 motion of one kind (`MOTION_KINDS`) or demo scene (`SCENE_MOTION`)."""
    kind = SCENE_MOTION.get(kind, kind)
    t = np.arange(int(round(seconds * rate))) / rate
    body_acc, gyro = MOTIONS[kind](rng, t, rate)
    rotation = _orientation(rng)
    gravity = np.array([0.0, 0.0, G])
    acc = (body_acc + gravity) @ rotation.T
    acc += 0.02 * rng.normal(size=acc.shape)  # the sensor's own noise
    return np.concatenate([acc, gyro @ rotation.T], axis=1).astype(np.float32)


def synth_ambient(
    scene: str,
    rng: np.random.Generator,
    seconds: float = DEFAULT_WINDOW_SECONDS,
    rate: int = AMBIENT_RATE,
    weather_hpa: float = SEA_LEVEL_HPA,
    place: np.random.Generator | None = None,
) -> np.ndarray:
    """(n, 3) float32 lux, °C, hPa in a demo scene, around its typical light and warmth.

    Where one stands (by the window, in a corner) is drawn from `place` (default: `rng`): a
    stream cut into stretches passes the same `place` for every stretch of one stay, or its
    light and warmth would jump at each stretch's start, as no real room does."""
    lux, celsius = SCENE_AMBIENT[scene]
    n = int(round(seconds * rate))
    where = place if place is not None else rng
    level = lux * np.exp(where.normal(0, 0.25))
    warmth_offset, pressure_offset = where.normal(0, 0.7), where.normal(0, 0.3)
    light = level * np.exp(0.05 * rng.normal(size=n))
    warmth = celsius + warmth_offset + 0.05 * rng.normal(size=n)
    pressure = weather_hpa + pressure_offset + 0.03 * rng.normal(size=n)
    return np.stack([light, warmth, pressure], axis=1).astype(np.float32)


def write_sensor_library(
    root: str | Path, seed: int = 0, windows_per_scene: int = 6, scenes: Sequence[str] = DEMO_SCENES
) -> Path:
    """Synthesised windows as a scene library under `root`: `<scene>/demo-NN.imu.csv` and
    `<scene>/demo-NN.ambient.csv`, as teach mode would keep them."""
    root = Path(root)
    for s, scene in enumerate(scenes):
        for i in range(windows_per_scene):
            rng = np.random.default_rng([seed, LIBRARY_STREAM, s, i])
            stem = root / scene / f"demo-{i:02d}"
            write_sample_csv(f"{stem}{SUFFIXES['imu']}", synth_motion(scene, rng), IMU_RATE, "imu")
            write_sample_csv(
                f"{stem}{SUFFIXES['ambient']}", synth_ambient(scene, rng), AMBIENT_RATE, "ambient"
            )
    return root
