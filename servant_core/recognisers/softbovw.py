"""`softbovw`: K-Means visual and colour words, soft-encoded, with a discriminative head.

A picture's central square: dense blocks (`features.descriptors`) triangle-encoded against K-Means
visual and colour words, averaged over the picture and a spatial pyramid, and an HSV histogram; a
multinomial logistic head over them (regularisation by stratified cross-validation, one-standard-
error rule; pictures also learned mirrored, `mirrored`). A picture farther than the training
pictures' own distances (times a margin) from every place's centroid is "unknown place". `fold_in`
keeps the codebooks and the regularisation and refits the head with the new rows."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar, Self

import numpy as np
from sklearn.cluster import KMeans
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import balanced_accuracy_score
from sklearn.model_selection import StratifiedKFold

from servant_core.features.descriptors import (
    DEFAULT_BINS,
    DEFAULT_CELL,
    DEFAULT_HSV_BINS,
    DEFAULT_SIZE,
    block_descriptors,
    hsv_histogram,
    square_thumbnail,
)
from servant_core.recognisers.base import PERCENT, check_training_scenes, init_params
from servant_core.recognisers.centroids import SceneCentroids, spherical_kmeans
from servant_core.recognisers.linear_head import LinearHeadAnswers

C_GRID = (0.001, 0.003, 0.01, 0.03, 0.1)
COLOUR_DIM = 12


def triangle_activations(rows: np.ndarray, words: np.ndarray) -> np.ndarray:
    """(..., K) Coates & Ng's triangle encoding of (..., d) rows against (K, d) words:
    max(0, μ − z_k), z_k the distance to word k and μ the mean of a row's distances."""
    squared = (
        np.sum(rows**2, axis=-1, keepdims=True) - 2 * rows @ words.T + np.sum(words**2, axis=1)
    )
    z = np.sqrt(np.maximum(squared, 0.0))
    return np.maximum(z.mean(axis=-1, keepdims=True) - z, 0.0)


def mirrored(gradients: np.ndarray, colours: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The block descriptors of the left-right mirror image, from (n, side², 4·n_bins) gradient
    and (n, side², 12) colour blocks: the grid's columns reversed, each block's left and right
    cells swapped, and each cell's orientations θ → π − θ (bins reversed). Exact but for
    gradients lying exactly on a bin edge."""
    n, n_blocks, width = gradients.shape
    side = int(round(np.sqrt(n_blocks)))
    swap = [1, 0, 3, 2]  # blocks list their cells top-left, top-right, bottom-left, bottom-right
    g = gradients.reshape(n, side, side, 4, width // 4)[:, :, ::-1][:, :, :, swap][..., ::-1]
    c = colours.reshape(n, side, side, 4, -1)[:, :, ::-1][:, :, :, swap]
    return g.reshape(gradients.shape), c.reshape(colours.shape)


def one_standard_error_choice(scores: np.ndarray) -> int:
    """Of (settings, folds) scores, settings ordered simplest first: the first setting whose mean
    is within one standard error (of the best setting's folds) of the best mean."""
    means = scores.mean(axis=1)
    best = int(np.argmax(means))
    error = scores[best].std(ddof=1) / np.sqrt(scores.shape[1])
    return int(np.flatnonzero(means >= means[best] - error)[0])


def region_masks(n_blocks: int, grids: Sequence[int]) -> np.ndarray:
    """(regions, n_blocks) masks of a square row-major block grid cut into g×g regions for each
    g in `grids` (g = 1: the whole picture)."""
    side = int(round(np.sqrt(n_blocks)))
    rows, cols = np.divmod(np.arange(side * side), side)
    masks = []
    for g in grids:
        region = (rows * g // side) * g + cols * g // side
        masks += [region == r for r in range(g * g)]
    return np.asarray(masks)


def pooled(activations: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """(n, regions·K): the mean activation of each word over each region of each picture."""
    counts = masks.sum(axis=1)
    per_region = np.einsum("rb,nbk->nrk", masks.astype(activations.dtype), activations)
    return (per_region / counts[None, :, None]).reshape(len(activations), -1)


class SoftBovwVisualRecogniser(LinearHeadAnswers):
    method: ClassVar[str] = "softbovw"
    sense: ClassVar[str] = "image"
    confidence_unit: ClassVar[str] = PERCENT

    def __init__(
        self,
        *,
        size: int = DEFAULT_SIZE,
        cell: int = DEFAULT_CELL,
        n_bins: int = DEFAULT_BINS,
        n_words: int = 128,
        n_colour_words: int = 64,
        grids: Sequence[int] = (1, 2),
        hsv_bins: Sequence[int] = DEFAULT_HSV_BINS,
        mirror: bool = True,
        C: float | None = None,
        cv_folds: int = 4,
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
        self.grids = grids
        self.hsv_bins = hsv_bins
        self.mirror = mirror
        self.C = C
        self.cv_folds = cv_folds
        self.max_codebook_blocks = max_codebook_blocks
        self.reject_quantile = reject_quantile
        self.reject_margin = reject_margin
        self.random_state = random_state

    def params(self) -> dict[str, Any]:
        return init_params(self)

    # --- features --------------------------------------------------------------------------

    def _block_dim(self) -> int:
        return 4 * self.n_bins + COLOUR_DIM

    def featurize(self, pictures: Sequence[np.ndarray]) -> np.ndarray:
        """(n, blocks·(4·n_bins + 12) + hsv bins) float32: each picture's block descriptors,
        flattened, then its HSV histogram (one row a picture, as the other methods)."""
        rows = []
        for picture in pictures:
            gradients, colours = block_descriptors(picture, self.size, self.cell, self.n_bins)
            hsv = hsv_histogram(square_thumbnail(picture, self.size), self.hsv_bins)
            rows.append(np.concatenate([np.concatenate([gradients, colours], axis=1).ravel(), hsv]))
        return np.asarray(rows, dtype=np.float32)

    def _split(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Gradient blocks (n, b, 4·n_bins), colour blocks (n, b, 12), HSV histograms (n, h)."""
        X = np.asarray(X, dtype=np.float32)
        n_hsv = int(np.prod(self.hsv_bins))
        block = X[:, :-n_hsv].reshape(len(X), -1, self._block_dim())
        return block[..., : 4 * self.n_bins], block[..., 4 * self.n_bins :], X[:, -n_hsv:]

    def _fit_codebooks(self, X: np.ndarray) -> None:
        gradients, colours, _ = self._split(X)
        self.words_ = spherical_kmeans(
            gradients.reshape(-1, gradients.shape[-1]),
            self.n_words,
            self.max_codebook_blocks,
            self.random_state,
        )
        flat = colours.reshape(-1, COLOUR_DIM)
        rng = np.random.default_rng(self.random_state)
        if len(flat) > self.max_codebook_blocks:
            flat = flat[rng.choice(len(flat), self.max_codebook_blocks, replace=False)]
        kmeans = KMeans(
            n_clusters=min(self.n_colour_words, len(flat)), n_init=1, random_state=self.random_state
        ).fit(flat)
        self.colour_words_ = kmeans.cluster_centers_.astype(np.float32)

    def describe(self, X: np.ndarray) -> np.ndarray:
        """Pooled triangle activations of both codebooks and the square-rooted HSV histogram."""
        return self._encode(*self._split(X))

    def _described_mirrors(self, X: np.ndarray) -> np.ndarray:
        gradients, colours, hsv = self._split(X)
        # the mirror image has the same colour histogram
        return self._encode(*mirrored(gradients, colours), hsv)

    def _encode(self, gradients: np.ndarray, colours: np.ndarray, hsv: np.ndarray) -> np.ndarray:
        masks = region_masks(gradients.shape[1], self.grids)
        return np.concatenate(
            [
                pooled(triangle_activations(gradients, self.words_), masks),
                pooled(triangle_activations(colours, self.colour_words_), masks),
                np.sqrt(hsv),
            ],
            axis=1,
        )

    def _standardised(self, X: np.ndarray) -> np.ndarray:
        self._check_fitted()
        return (self.describe(X) - self.mean_) / self.scale_

    # --- fitting ---------------------------------------------------------------------------

    def fit(self, X: np.ndarray, scenes: Sequence[str] | np.ndarray) -> Self:
        check_training_scenes(scenes, len(X))
        self._fit_codebooks(X)
        D = self.describe(X)
        labels = np.asarray(scenes).astype(str)
        mirrors = self._described_mirrors(X) if self.mirror else D[:0]
        both = np.vstack([D, mirrors])
        self.mean_ = both.mean(axis=0)
        std = both.std(axis=0)
        # a word no training block uses has no spread; it must not divide by zero
        self.scale_ = np.where(std > 1e-9, std, 1.0)
        D = (D - self.mean_) / self.scale_
        mirrors = (mirrors - self.mean_) / self.scale_
        self.C_ = self.C if self.C is not None else self._choose_C(D, mirrors, labels)
        self.train_rows_ = np.vstack([D, mirrors]).astype(np.float32)
        self.train_scenes_ = np.concatenate([labels, labels[: len(mirrors)]])
        self._fit_head()
        self.novelty_head_ = SceneCentroids.fit(
            D, labels, 1, self.reject_quantile, self.reject_margin, self.random_state
        )
        return self

    def _head(self, C: float) -> LogisticRegression:
        # balanced: a scene with three times the pictures must not win every doubtful picture
        return LogisticRegression(C=C, class_weight="balanced", max_iter=2000)

    def _choose_C(self, D: np.ndarray, mirrors: np.ndarray, labels: np.ndarray) -> float:
        """The regularisation chosen by stratified folds of the training pictures (a picture and
        its mirror always on the same side): the smallest C (the most regularised) whose mean
        balanced accuracy is within one standard error of the best (Breiman's one-standard-error
        rule: new pictures come from places the folds never show, where the simpler head holds
        up better). The smallest C of the grid when there are too few pictures to fold."""
        smallest = int(min(np.unique(labels, return_counts=True)[1]))
        folds = min(self.cv_folds, smallest)
        if folds < 2:
            return C_GRID[0]
        cv = StratifiedKFold(folds, shuffle=True, random_state=self.random_state)
        scores = np.zeros((len(C_GRID), folds))
        for k, (train, test) in enumerate(cv.split(D, labels)):
            mirrored_train = train[train < len(mirrors)]
            X = np.vstack([D[train], mirrors[mirrored_train]])
            y = np.concatenate([labels[train], labels[mirrored_train]])
            for i, C in enumerate(C_GRID):
                head = self._head(C).fit(X, y)
                scores[i, k] = balanced_accuracy_score(labels[test], head.predict(D[test]))
        return float(C_GRID[one_standard_error_choice(scores)])

    def _fit_head(self) -> None:
        self.head_ = self._head(self.C_).fit(self.train_rows_, self.train_scenes_)

    # --- using it --------------------------------------------------------------------------

    def _space(self, X: np.ndarray) -> np.ndarray:
        return self._standardised(X)

    def fold_in(self, X: np.ndarray, scenes: Sequence[str]) -> Self:
        """Add pictures with confirmed scenes (a new scene too): codebooks, standardisation and
        C stay; the head is refitted on the kept training rows plus these."""
        if len(scenes) != len(X):
            raise ValueError(f"{len(X)} feature rows but {len(scenes)} scene labels")
        D = self._standardised(X)
        labels = np.asarray(scenes).astype(str)
        new = [D]
        if self.mirror:
            new.append((self._described_mirrors(X) - self.mean_) / self.scale_)
        self.train_rows_ = np.vstack([self.train_rows_, *new]).astype(np.float32)
        self.train_scenes_ = np.concatenate([self.train_scenes_, *[labels] * len(new)])
        self._fit_head()
        self.novelty_head_.fold_in(D, list(scenes))
        return self

    # --- model files -----------------------------------------------------------------------

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        self._check_fitted()
        novelty, novelty_arrays = self.novelty_head_.state()
        header = {"params": self.params(), "C_": self.C_, "novelty": novelty}
        arrays = {
            "words": self.words_,
            "colour_words": self.colour_words_,
            "mean": self.mean_,
            "scale": self.scale_,
            "train_rows": self.train_rows_,
            # scenes as indices into the sorted scene list: no object arrays in the file
            "train_scenes": np.searchsorted(self.scenes_, self.train_scenes_),
            "coef": self.head_.coef_,
            "intercept": self.head_.intercept_,
            **{f"novelty_{k}": v for k, v in novelty_arrays.items()},
        }
        header["scenes"] = self.scenes_
        return header, arrays

    @classmethod
    def from_state(cls, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        model = cls(**header["params"])
        model.words_ = np.asarray(arrays["words"], dtype=np.float32)
        model.colour_words_ = np.asarray(arrays["colour_words"], dtype=np.float32)
        model.mean_ = np.asarray(arrays["mean"], dtype=np.float64)
        model.scale_ = np.asarray(arrays["scale"], dtype=np.float64)
        model.C_ = float(header["C_"])
        model.train_rows_ = np.asarray(arrays["train_rows"], dtype=np.float32)
        model.train_scenes_ = np.asarray(header["scenes"])[
            np.asarray(arrays["train_scenes"], dtype=np.intp)
        ]
        head = model._head(model.C_)
        head.classes_ = np.asarray(header["scenes"])
        head.coef_ = np.asarray(arrays["coef"], dtype=np.float64)
        head.intercept_ = np.asarray(arrays["intercept"], dtype=np.float64)
        head.n_features_in_ = head.coef_.shape[1]
        model.head_ = head
        prefixed = {k[len("novelty_") :]: v for k, v in arrays.items() if k.startswith("novelty_")}
        model.novelty_head_ = SceneCentroids.from_state(header["novelty"], prefixed)
        return model
