"""Ambient features: the light, warmth and pressure of a window, as a few numbers.

Light is taken on a log scale (a café's 250 lux and daylight's 10,000 differ by a factor, not
a sum; the eye and the sensor both span six orders of magnitude). Pressure is used only through
its change (hPa per minute: a lift, stairs, a hill) and its jitter, never its level: the level
follows the weather far more than the place, and would teach the model the day it was taught.
"""

from __future__ import annotations

import numpy as np

MIN_LUX = 0.1  # darker than this reads as this: the log of a dark room stays finite
AMBIENT_FEATURES = (
    "log_lux_mean",
    "log_lux_std",
    "celsius_mean",
    "celsius_std",
    "hpa_per_minute",
    "hpa_std",
)


def trend_per_minute(values: np.ndarray, rate: float) -> float:
    """The least-squares slope of `values` (1-D, at `rate` a second), per minute."""
    t = np.arange(len(values)) / rate
    if len(values) < 2:
        return 0.0
    return float(np.polyfit(t, np.asarray(values, dtype=np.float64), 1)[0] * 60.0)


def ambient_features(window: np.ndarray, rate: float) -> np.ndarray:
    """The `AMBIENT_FEATURES` of one (n, 3) window: lux, °C, hPa."""
    window = np.asarray(window, dtype=np.float64)
    if window.ndim != 2 or window.shape[1] != 3 or len(window) < 1:
        raise ValueError("expected an ambient window of shape (n >= 1, 3)")
    light = np.log10(np.maximum(window[:, 0], MIN_LUX))
    celsius, hpa = window[:, 1], window[:, 2]
    return np.array(
        [
            light.mean(),
            light.std(),
            celsius.mean(),
            celsius.std(),
            trend_per_minute(hpa, rate),
            hpa.std(),
        ]
    )
