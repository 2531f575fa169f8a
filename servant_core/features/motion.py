"""Motion features: what a window of accelerometer and gyroscope readings says about activity.

The acceleration's magnitude is used, not its three axes: it does not depend on how the sensor
is worn. From it, its spread and its energy in frequency bands (the 1–3 Hz cadence band, the
8–20 Hz vibration band). The gyroscope's magnitude adds how much the body turns. Energies are on
a log scale.
"""

from __future__ import annotations

import numpy as np

# frequency bands (Hz): slow sway, walking cadence, brisk movement, vehicle vibration
BANDS = ((0.3, 1.0), (1.0, 3.0), (3.0, 8.0), (8.0, 20.0))
CADENCE_RANGE = (0.5, 4.0)
FLOOR = 1e-6  # (m/s²)²: below the sensor's noise; keeps the logarithm of still windows finite
MOTION_FEATURES = (
    "acc_mean",
    "acc_log_std",
    "acc_log_range",
    *(f"band_{low:g}_{high:g}_log" for low, high in BANDS),
    "cadence_hz",
    "gyro_log_energy",
    "gyro_log_std",
)


def band_energies(
    x: np.ndarray, rate: float, bands: tuple[tuple[float, float], ...] = BANDS
) -> np.ndarray:
    """The variance of `x` (1-D) falling in each band [low, high) Hz (Hann-windowed spectrum
    scaled so that a sine of amplitude A in a band gives about A²/2); bands above the Nyquist
    frequency get 0."""
    x = np.asarray(x, dtype=np.float64)
    x = x - x.mean()
    window = np.hanning(len(x))
    spectrum = np.abs(np.fft.rfft(x * window)) ** 2 * 2 / (len(x) * np.sum(window**2))
    freqs = np.fft.rfftfreq(len(x), 1.0 / rate)
    return np.array([spectrum[(freqs >= low) & (freqs < high)].sum() for low, high in bands])


def dominant_frequency(x: np.ndarray, rate: float, band: tuple[float, float]) -> float:
    """The frequency (Hz) of the strongest spectral line of `x` within `band`; 0 if none."""
    x = np.asarray(x, dtype=np.float64)
    spectrum = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(len(x))))
    freqs = np.fft.rfftfreq(len(x), 1.0 / rate)
    inside = (freqs >= band[0]) & (freqs <= band[1])
    if not inside.any() or spectrum[inside].max() <= 0:
        return 0.0
    return float(freqs[inside][np.argmax(spectrum[inside])])


def motion_features(window: np.ndarray, rate: float) -> np.ndarray:
    """The `MOTION_FEATURES` of one (n, 6) window: ax, ay, az (m/s²), gx, gy, gz (deg/s)."""
    window = np.asarray(window, dtype=np.float64)
    if window.ndim != 2 or window.shape[1] != 6 or len(window) < 4:
        raise ValueError("expected a motion window of shape (n >= 4, 6)")
    magnitude = np.linalg.norm(window[:, :3], axis=1)
    turning = np.linalg.norm(window[:, 3:], axis=1)
    low, high = np.percentile(magnitude, [5, 95])
    return np.array(
        [
            magnitude.mean(),
            0.5 * np.log10(magnitude.var() + FLOOR),
            np.log10(high - low + FLOOR),
            *np.log10(band_energies(magnitude, rate) + FLOOR),
            dominant_frequency(magnitude, rate, CADENCE_RANGE),
            np.log10(np.mean(turning**2) + FLOOR),
            0.5 * np.log10(turning.var() + FLOOR),
        ]
    )
