"""Modulation spectra of log-mel frames: how fast each part of the spectrum rises and falls.

Babble's syllables (~4 Hz), cars passing (well under 1 Hz), a train's wheels on the rail joints:
a place's rhythms, which a change of microphone should leave alone. The band envelopes are log
energies with their own mean over the window removed, so neither the level nor a fixed
colouration (an equaliser adds a constant to each band's log energy) reaches the spectrum.
"""

from __future__ import annotations

import numpy as np

# Log-spaced modulation bins (Hz): 0.5–1, 1–2, 2–4, 4–8, 8–16.
MODULATION_EDGES = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
# Added to every bin's energy before the log (log10 units²): a still band (a steady hum) gives a
# finite value, not the log of rounding noise.
MODULATION_FLOOR = 1e-6
# The envelopes are zero-padded to at least this many frames before the Fourier transform: a
# quarter-window crop and a whole window (~214 frames at 22,050 Hz) share one frequency grid.
MIN_TRANSFORM = 256


def band_groups(frames: np.ndarray, groups: int) -> np.ndarray:
    """(n, frames, groups): the mean log energy of `groups` contiguous runs of bands of
    (n, frames, bands) frames."""
    edges = np.linspace(0, frames.shape[-1], groups + 1).round().astype(int)
    return np.stack(
        [frames[..., a:b].mean(axis=-1) for a, b in zip(edges[:-1], edges[1:], strict=True)],
        axis=-1,
    )


def modulation_spectrum(
    frames: np.ndarray,
    frame_rate: float,
    groups: int,
    edges: tuple[float, ...] = MODULATION_EDGES,
) -> np.ndarray:
    """(n, groups·bins) log10 modulation energies of (n, frames, bands) log-mel windows, each
    group's bins side by side.

    Each group's envelope, its mean removed and Hann-tapered, is Fourier-transformed; its power
    (per unit of the taper's energy, so a crop and a window are on one scale) is averaged within
    each bin of `edges` (Hz).
    """
    n, t, _ = frames.shape
    envelope = band_groups(np.asarray(frames, dtype=np.float32), groups)
    envelope = envelope - envelope.mean(axis=1, keepdims=True)
    taper = np.hanning(t).astype(np.float32)
    size = max(MIN_TRANSFORM, 1 << int(np.ceil(np.log2(t))))
    power = np.abs(np.fft.rfft(envelope * taper[None, :, None], n=size, axis=1)) ** 2
    power /= np.sum(taper**2)
    freqs = np.fft.rfftfreq(size, d=1.0 / frame_rate)
    bins = [
        power[:, (freqs >= low) & (freqs < high)].mean(axis=1)
        for low, high in zip(edges[:-1], edges[1:], strict=True)
    ]
    return np.log10(np.stack(bins, axis=-1) + MODULATION_FLOOR).reshape(n, -1)
