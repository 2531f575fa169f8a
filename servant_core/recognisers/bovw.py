"""`bovw`: the visual method beyond the paper, a bag of visual words with colour words.

A picture's dense blocks (`features.descriptors`: gradient orientations, mean L*a*b* colour) are
counted against K-Means visual words (spherical, on the gradients) and colour words, over the
picture and each quarter (a two-level pyramid), square-rooted. Each scene's descriptors are a few
centroids with their spreads (`SceneCentroids`): probabilities from distances, "unknown place"
when far from all.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from sklearn.cluster import KMeans

from servant_core.features.descriptors import (
    DEFAULT_BINS,
    DEFAULT_CELL,
    DEFAULT_SIZE,
    dense_descriptors,
)
from servant_core.recognisers.base import init_params
from servant_core.recognisers.centroids import (
    CentroidRecogniser,
    codeword_histograms,
    spherical_kmeans,
)


def quadrant_of_blocks(n_blocks: int) -> np.ndarray:
    """For a square row-major grid of `n_blocks` blocks, which quarter (0–3) each block is in."""
    side = int(round(np.sqrt(n_blocks)))
    rows, cols = np.divmod(np.arange(side * side), side)
    return (2 * (rows >= side / 2) + (cols >= side / 2)).astype(np.intp)


def pyramid_histograms(words: np.ndarray, n_words: int) -> np.ndarray:
    """(n, 5·n_words): word shares over the whole picture, then over each of its quarters."""
    quadrant = quadrant_of_blocks(words.shape[1])
    parts = [codeword_histograms(words, n_words)]
    for q in range(4):
        parts.append(codeword_histograms(words[:, quadrant == q], n_words))
    return np.concatenate(parts, axis=1)


class BovwVisualRecogniser(CentroidRecogniser):
    method: ClassVar[str] = "bovw"
    sense: ClassVar[str] = "image"

    def __init__(
        self,
        *,
        size: int = DEFAULT_SIZE,
        cell: int = DEFAULT_CELL,
        n_bins: int = DEFAULT_BINS,
        n_words: int = 128,
        n_colour_words: int = 32,
        colour_weight: float = 1.0,
        clusters_per_scene: int = 3,
        spread_shrinkage: float = 0.0,
        whitened_novelty: bool = False,
        discriminant: bool = True,
        max_codebook_blocks: int = 30000,
        reject_quantile: float = 0.95,
        reject_margin: float = 1.5,
        random_state: int | None = 0,
    ) -> None:
        self.size = size
        self.cell = cell
        self.n_bins = n_bins
        self.n_words = n_words
        self.n_colour_words = n_colour_words
        self.colour_weight = colour_weight
        self.clusters_per_scene = clusters_per_scene
        self.spread_shrinkage = spread_shrinkage
        self.discriminant = discriminant
        self.whitened_novelty = whitened_novelty
        self.max_codebook_blocks = max_codebook_blocks
        self.reject_quantile = reject_quantile
        self.reject_margin = reject_margin
        self.random_state = random_state

    def params(self) -> dict[str, Any]:
        return init_params(self)

    def featurize(self, pictures: Sequence[np.ndarray]) -> np.ndarray:
        """(n, blocks, 4·n_bins + 3) dense block descriptors of BGR pictures."""
        return np.stack([dense_descriptors(p, self.size, self.cell, self.n_bins) for p in pictures])

    def _split(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        X = np.asarray(X, dtype=np.float32)
        return X[..., : 4 * self.n_bins], X[..., 4 * self.n_bins :]

    def _fit_codebooks(self, X: np.ndarray) -> None:
        gradients, colours = self._split(X)
        self.words_ = spherical_kmeans(
            gradients.reshape(-1, gradients.shape[-1]),
            self.n_words,
            self.max_codebook_blocks,
            self.random_state,
        )
        rng = np.random.default_rng(self.random_state)
        flat = colours.reshape(-1, colours.shape[-1])
        if len(flat) > self.max_codebook_blocks:
            flat = flat[rng.choice(len(flat), self.max_codebook_blocks, replace=False)]
        kmeans = KMeans(
            n_clusters=min(self.n_colour_words, len(flat)), n_init=1, random_state=self.random_state
        ).fit(flat)
        self.colour_words_ = kmeans.cluster_centers_.astype(np.float32)

    def words(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(n, blocks) visual word and colour word of each block."""
        gradients, colours = self._split(X)
        visual = np.argmax(gradients @ self.words_.T, axis=-1)
        squared = (
            np.sum(colours**2, axis=-1, keepdims=True)
            - 2 * colours @ self.colour_words_.T
            + np.sum(self.colour_words_**2, axis=1)
        )
        return visual, np.argmin(squared, axis=-1)

    def describe(self, X: np.ndarray) -> np.ndarray:
        visual, colour = self.words(X)
        return np.concatenate(
            [
                np.sqrt(pyramid_histograms(visual, len(self.words_))),
                self.colour_weight * np.sqrt(pyramid_histograms(colour, len(self.colour_words_))),
            ],
            axis=1,
        )

    def _codebook_arrays(self) -> dict[str, np.ndarray]:
        return {"words": self.words_, "colour_words": self.colour_words_}

    def _load_codebook_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        self.words_ = np.asarray(arrays["words"], dtype=np.float32)
        self.colour_words_ = np.asarray(arrays["colour_words"], dtype=np.float32)
