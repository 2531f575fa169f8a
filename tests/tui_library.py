"""A small scene library written by the tests themselves: two scenes of filtered noise and
pictures in two palettes, enough windows for the temporal protocol."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from servant_core.audio import write_wav

RATE = 8000


def noise_recording(seconds: float, centre_hz: float, seed: int) -> np.ndarray:
    """Noise with a band around `centre_hz`: scenes that sound apart, reproducibly."""
    rng = np.random.default_rng(seed)
    n = int(seconds * RATE)
    spectrum = np.fft.rfft(rng.normal(size=n))
    freqs = np.fft.rfftfreq(n, 1 / RATE)
    spectrum *= np.exp(-(((freqs - centre_hz) / 150.0) ** 2)) + 0.05
    signal = np.fft.irfft(spectrum, n)
    return (0.3 * signal / np.abs(signal).max()).astype(np.float32)


def write_library(root: Path) -> Path:
    for i, (scene, centre, bgr) in enumerate(
        (("cafe", 500.0, (40, 60, 120)), ("street", 2500.0, (120, 120, 120)))
    ):
        for r in range(2):
            write_wav(
                root / scene / f"rec{r}.wav", noise_recording(30.0, centre, seed=10 * i + r), RATE
            )
        for p in range(2):
            picture = np.full((32, 32, 3), bgr, dtype=np.uint8)
            picture[: 8 * (p + 1)] = (255, 255, 255)
            cv2.imwrite(str(root / scene / f"pic{p}.png"), picture)
    return root
