"""Log-mel frames over the band every recording has, with the level taken out.

Recordings come at 24, 44.1 and 48 kHz: a 24 kHz file has nothing above 12 kHz, so anything
that looks above ~11 kHz learns the microphone, not the place. The mel bands stop at `fmax`
(10.5 kHz by default), below every recording's Nyquist frequency. A quieter café is still a
café: log energies are taken relative to the window's own mean level, so a gain is cancelled.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

DEFAULT_RATE = 22050
DEFAULT_N_FFT = 1024
DEFAULT_HOP = 512
DEFAULT_N_MELS = 40
DEFAULT_FMIN = 60.0
DEFAULT_FMAX = 10500.0
# Energies more than 80 dB below the window's loudest band are treated as that floor: it keeps the
# log finite, and being relative to the window it scales with the gain, so it cancels too.
DYNAMIC_RANGE = 1e-8


def hz_to_mel(hz: np.ndarray | float) -> np.ndarray:
    """HTK mel scale: 2595 log10(1 + f/700)."""
    return 2595.0 * np.log10(1.0 + np.asarray(hz, dtype=float) / 700.0)


def mel_to_hz(mel: np.ndarray | float) -> np.ndarray:
    return 700.0 * (10.0 ** (np.asarray(mel, dtype=float) / 2595.0) - 1.0)


@lru_cache(maxsize=8)
def mel_filterbank(rate: int, n_fft: int, n_mels: int, fmin: float, fmax: float) -> np.ndarray:
    """(n_mels, n_fft // 2 + 1) triangular filters, equally spaced in mel, each of unit area."""
    if not 0 <= fmin < fmax <= rate / 2:
        raise ValueError(f"mel band {fmin}-{fmax} Hz does not fit below Nyquist ({rate / 2} Hz)")
    bins = np.fft.rfftfreq(n_fft, d=1.0 / rate)
    edges = mel_to_hz(np.linspace(hz_to_mel(fmin), hz_to_mel(fmax), n_mels + 2))
    lower, centre, upper = edges[:-2, None], edges[1:-1, None], edges[2:, None]
    rising = (bins[None, :] - lower) / (centre - lower)
    falling = (upper - bins[None, :]) / (upper - centre)
    filters = np.maximum(0.0, np.minimum(rising, falling))
    filters /= np.maximum(filters.sum(axis=1, keepdims=True), 1e-12)
    filters.setflags(write=False)
    return filters


def frame_signal(window: np.ndarray, n_fft: int, hop: int) -> np.ndarray:
    """(frames, n_fft) overlapping frames of a mono window (a strided view; the tail is dropped)."""
    window = np.ascontiguousarray(window, dtype=np.float32)
    if len(window) < n_fft:
        window = np.pad(window, (0, n_fft - len(window)))
    return np.lib.stride_tricks.sliding_window_view(window, n_fft)[::hop]


def log_mel_frames(
    window: np.ndarray,
    rate: int = DEFAULT_RATE,
    n_fft: int = DEFAULT_N_FFT,
    hop: int = DEFAULT_HOP,
    n_mels: int = DEFAULT_N_MELS,
    fmin: float = DEFAULT_FMIN,
    fmax: float = DEFAULT_FMAX,
) -> np.ndarray:
    """(frames, n_mels) log10 mel energies of one window, minus the window's mean level.

    Subtracting the mean over all frames and bands cancels any constant gain (a quieter or
    louder recording of the same place gives the same frames).
    """
    frames = frame_signal(window, n_fft, hop) * np.hanning(n_fft).astype(np.float32)
    power = np.abs(np.fft.rfft(frames, axis=1)) ** 2
    energies = power @ mel_filterbank(rate, n_fft, n_mels, fmin, fmax).T
    floor = max(float(energies.max()) * DYNAMIC_RANGE, float(np.finfo(np.float32).tiny))
    log_energies = np.log10(np.maximum(energies, floor))
    return (log_energies - log_energies.mean()).astype(np.float32)


def fft_length(rate: int, frame_seconds: float) -> int:
    """The FFT length of `log_mel_windows`: a power of two near `frame_seconds` at `rate`."""
    return int(2 ** round(np.log2(frame_seconds * rate)))


def frame_rate(rate: int, frame_seconds: float) -> float:
    """Frames a second of `log_mel_windows` (half-overlapping frames)."""
    return rate / (fft_length(rate, frame_seconds) // 2)


def log_mel_windows(
    windows: np.ndarray,
    rate: int,
    frame_seconds: float,
    n_mels: int,
    fmin: float = DEFAULT_FMIN,
    fmax: float = DEFAULT_FMAX,
) -> np.ndarray:
    """(n, frames, n_mels) level-free log-mel frames of (n, samples) windows at `rate`.

    The FFT length follows the rate (a power of two near `frame_seconds`, half-overlapping), so
    a model at 44.1 kHz sees the same time–frequency tiles as one at 22.05 kHz; `fmax` stays
    below the rate's Nyquist frequency.
    """
    windows = np.atleast_2d(np.asarray(windows, dtype=np.float32))
    n_fft = fft_length(rate, frame_seconds)
    fmax = min(fmax, 0.475 * rate)
    return np.stack(
        [log_mel_frames(w, rate, n_fft, n_fft // 2, n_mels, fmin, fmax) for w in windows]
    )
