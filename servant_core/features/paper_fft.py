"""The paper's acoustic feature: the FFT's frequency array with its amplitude array appended."""

from __future__ import annotations

import numpy as np

# The paper read its WAVs as 16-bit integers, so its amplitudes are in PCM units; its confidence
# formula (eq. 1, divided by 10000) is on that scale. We keep float audio in [-1, 1] and scale
# by 2^15 here so that eq. 1 gives numbers of the paper's order.
PCM_SCALE = 32768.0


def paper_fft_vector(window: np.ndarray, rate: int) -> np.ndarray:
    """[frequencies (Hz) | |FFT| amplitudes] of one mono window, as one 1-D float32 vector.

    One-sided (rfft): for a real signal the negative half repeats the positive half.
    """
    n = len(window)
    freqs = np.fft.rfftfreq(n, d=1.0 / rate)
    amps = np.abs(np.fft.rfft(np.asarray(window, dtype=np.float64) * PCM_SCALE))
    return np.concatenate([freqs, amps]).astype(np.float32)


def paper_fft_vectors(windows: np.ndarray, rate: int) -> np.ndarray:
    """paper_fft_vector for each row of a (n, samples) array, in one float32 (n, d) array."""
    windows = np.atleast_2d(windows)
    n, size = windows.shape
    half = size // 2 + 1
    out = np.empty((n, 2 * half), dtype=np.float32)
    out[:, :half] = np.fft.rfftfreq(size, d=1.0 / rate)
    for i in range(n):  # one window at a time keeps the float64/complex temporaries small
        out[i, half:] = np.abs(np.fft.rfft(windows[i] * PCM_SCALE))
    return out
