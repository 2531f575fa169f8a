"""`codebook`: the acoustic method beyond the paper, K-Means at its heart twice over.

A 5 s window becomes ~215 log-mel frames over 60 Hz–10.5 kHz, mean level removed; spherical
K-Means over the training frames (each centred, unit length) gives a codebook of sound shapes; a
window is its square-rooted codeword histogram (Hellinger). Each scene's windows are a few K-Means
centroids with their spreads: probabilities from distances, "unknown place" when far from all.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from servant_core.features.logmel import (
    DEFAULT_FMAX,
    DEFAULT_FMIN,
    DEFAULT_N_MELS,
    log_mel_frames,
)
from servant_core.recognisers.base import init_params
from servant_core.recognisers.centroids import (
    CentroidRecogniser,
    codeword_histograms,
    spherical_kmeans,
    unit_rows,
)

# 22,050 Hz: its Nyquist frequency (11,025 Hz) is below that of the 24 kHz recordings, so
# resampling every recording to it leaves no band that only some microphones fill.
CODEBOOK_RATE = 22050


def frame_shapes(frames: np.ndarray) -> np.ndarray:
    """Log-mel frames centred and scaled to unit length: the spectrum's shape, not its level."""
    return unit_rows(frames - frames.mean(axis=-1, keepdims=True))


class CodebookAcousticRecogniser(CentroidRecogniser):
    method: ClassVar[str] = "codebook"
    sense: ClassVar[str] = "audio"

    def __init__(
        self,
        *,
        rate: int = CODEBOOK_RATE,
        window_seconds: float = 5.0,
        n_mels: int = DEFAULT_N_MELS,
        frame_seconds: float = 0.046,
        fmin: float = DEFAULT_FMIN,
        fmax: float = DEFAULT_FMAX,
        n_codewords: int = 32,
        clusters_per_scene: int = 3,
        spread_shrinkage: float = 1.0,
        whitened_novelty: bool = True,
        discriminant: bool = False,
        max_codebook_frames: int = 20000,
        reject_quantile: float = 0.95,
        reject_margin: float = 1.7,
        random_state: int | None = 0,
    ) -> None:
        self.rate = rate
        self.window_seconds = window_seconds
        self.n_mels = n_mels
        self.frame_seconds = frame_seconds
        self.fmin = fmin
        self.fmax = fmax
        self.n_codewords = n_codewords
        self.clusters_per_scene = clusters_per_scene
        self.spread_shrinkage = spread_shrinkage
        self.discriminant = discriminant
        self.whitened_novelty = whitened_novelty
        self.max_codebook_frames = max_codebook_frames
        self.reject_quantile = reject_quantile
        self.reject_margin = reject_margin
        self.random_state = random_state

    def params(self) -> dict[str, Any]:
        return init_params(self)

    def featurize(self, windows: np.ndarray) -> np.ndarray:
        """(n, frames, n_mels) level-free log-mel frames of (n, samples) windows at `rate`.

        The FFT length follows the rate (a power of two near `frame_seconds`, half-overlapping),
        so a model at 44.1 kHz sees the same time–frequency tiles as one at 22.05 kHz.
        """
        windows = np.atleast_2d(np.asarray(windows, dtype=np.float32))
        n_fft = int(2 ** round(np.log2(self.frame_seconds * self.rate)))
        fmax = min(self.fmax, 0.475 * self.rate)
        return np.stack(
            [
                log_mel_frames(w, self.rate, n_fft, n_fft // 2, self.n_mels, self.fmin, fmax)
                for w in windows
            ]
        )

    def _fit_codebooks(self, X: np.ndarray) -> None:
        shapes = frame_shapes(np.asarray(X, dtype=np.float32))
        shapes = shapes.reshape(-1, shapes.shape[-1])
        self.codebook_ = spherical_kmeans(
            shapes, self.n_codewords, self.max_codebook_frames, self.random_state
        )

    def codewords(self, X: np.ndarray) -> np.ndarray:
        """(n, frames) index of each frame's codeword (largest cosine)."""
        return np.argmax(frame_shapes(np.asarray(X, dtype=np.float32)) @ self.codebook_.T, axis=-1)

    def describe(self, X: np.ndarray) -> np.ndarray:
        return np.sqrt(codeword_histograms(self.codewords(X), len(self.codebook_)))

    def _codebook_arrays(self) -> dict[str, np.ndarray]:
        return {"codebook": self.codebook_}

    def _load_codebook_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        self.codebook_ = np.asarray(arrays["codebook"], dtype=np.float32)
