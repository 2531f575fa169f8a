"""`fisher-bovw`: Fisher vectors over dense SIFT, with a linear head.

A picture's central square gives dense RootSIFT descriptors at two scales (`features.dense_sift`),
PCA'd to `pca_dim` with each patch's (x, y) appended, and its improved Fisher vector under a
diagonal Gaussian mixture of `n_components` (power- and L2-normalised), beside the square-rooted
HSV histogram weighted by `colour_weight`. The head is a balanced multinomial logistic regression
in the first `head_dim` principal directions, its regularisation chosen by held-out log loss
(`calibration`; each fold's mixture refined without the held-out pictures); training pictures are
also learned mirrored. A picture farther than the training pictures' own distances (times a
margin) from every place's centroid (`SceneCentroids`) is "unknown place". `fold_in` refits only
the head."""

from __future__ import annotations

import copy
import warnings
from collections.abc import Sequence
from typing import Any, ClassVar, Self

import numpy as np
import scipy.linalg
from sklearn.exceptions import ConvergenceWarning
from sklearn.linear_model import LogisticRegression
from sklearn.mixture import GaussianMixture

from servant_core.errors import ServantError
from servant_core.features.dense_sift import (
    DEFAULT_BIN_SIZES,
    DEFAULT_SIFT_SIZE,
    DEFAULT_STEP,
    SIFT_DIM,
    dense_root_sift,
    keypoint_positions,
    mirror_order,
)
from servant_core.features.descriptors import DEFAULT_HSV_BINS, hsv_histogram, square_thumbnail
from servant_core.features.fisher_vector import fisher_vectors, power_l2
from servant_core.recognisers.base import PERCENT, check_training_scenes, init_params
from servant_core.recognisers.calibration import least_regularised_within_error, settings_losses
from servant_core.recognisers.centroids import SceneCentroids
from servant_core.recognisers.linear_head import LinearHeadAnswers

# most regularised first; up to 1000, where a head of twelve pictures still gave pictures it never
# saw probabilities no surer than they were right (log loss 0.45 against 0.69 for a coin toss)
C_GRID = (0.01, 0.1, 1.0, 10.0, 100.0, 1000.0)
# each fold's mixture: the kept one refined by this many EM steps on this many of its pictures'
# descriptors (a few steps move the words made for the held-out pictures; the full fit takes ~70)
REFINE_STEPS = 3
REFINE_DESCRIPTORS = 10_000
# pictures a place that the folds hold out, at most: their cost stays bounded in a large library
CALIBRATION_PICTURES = 20
MIN_VARIANCE = 1e-4
# a 128-pixel square at the default grid has 685 patches; a model asking for many more (a
# doctored file: size 2048, step 1) would take gigabytes a picture
MAX_PATCHES = 20_000


def leading_directions(
    rows: np.ndarray, k: int, block: int = 1024
) -> tuple[np.ndarray, np.ndarray]:
    """The `k` largest singular values of `rows` (n, d), largest first, and their right
    singular vectors (k, d), from the smaller of its Gram matrices (summed in float64 a block at
    a time) and only its `k` leading eigenvectors. The same as `np.linalg.svd(rows)` up to each
    vector's sign; over a library's Fisher vectors (3,600 × 8,576) the full SVD took 1.3 GB."""
    n, d = rows.shape
    size = min(n, d)
    gram = np.zeros((size, size))
    for start in range(0, max(n, d), block):
        part = (rows[:, start : start + block] if n <= d else rows[start : start + block]).astype(
            np.float64
        )
        gram += part @ part.T if n <= d else part.T @ part
    k = min(k, size)
    values, vectors = scipy.linalg.eigh(gram, subset_by_index=[size - k, size - 1])
    values, vectors = values[::-1], vectors[:, ::-1]
    singular = np.sqrt(np.clip(values, 0.0, None))
    if n > d:
        return singular, vectors.T
    vt = np.empty((k, d))
    for start in range(0, d, block):
        vt[:, start : start + block] = vectors.T @ rows[:, start : start + block].astype(np.float64)
    return singular, vt / np.where(singular > 0, singular, 1.0)[:, None]


def head_space(encoded: np.ndarray, head_dim: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The head's space of (n, d) encoded training rows: their mean (d,), their leading principal
    directions (at most `head_dim`, none of zero spread; (k, d), none at all when every row is
    the same) and one scale for every direction, so the leading ones keep their larger share."""
    mean = encoded.mean(axis=0).astype(np.float32)
    centred = encoded - mean
    singular, vt = leading_directions(centred, head_dim)
    dims = min(head_dim, int(np.sum(singular > 1e-6 * singular[0])))
    directions = vt[:dims].astype(np.float32)
    scale = float(np.sqrt(np.mean((centred @ directions.T) ** 2))) if dims else 0.0
    return mean, directions, scale or 1.0


class FisherBovwVisualRecogniser(LinearHeadAnswers):
    method: ClassVar[str] = "fisher-bovw"
    sense: ClassVar[str] = "image"
    confidence_unit: ClassVar[str] = PERCENT

    def __init__(
        self,
        *,
        size: int = DEFAULT_SIFT_SIZE,
        bin_sizes: Sequence[int] = DEFAULT_BIN_SIZES,
        step: int = DEFAULT_STEP,
        pca_dim: int = 64,
        n_components: int = 64,
        xy: bool = True,
        hsv_bins: Sequence[int] = DEFAULT_HSV_BINS,
        colour_weight: float = 0.5,
        head_dim: int = 256,
        mirror: bool = True,
        C: float | None = None,
        cv_folds: int = 4,
        max_mixture_descriptors: int = 50000,
        reject_quantile: float = 0.95,
        reject_margin: float = 1.5,
        random_state: int | None = 0,
    ) -> None:
        self.size = size
        self.bin_sizes = bin_sizes
        self.step = step
        self.pca_dim = pca_dim
        self.n_components = n_components
        self.xy = xy
        self.hsv_bins = hsv_bins
        self.colour_weight = colour_weight
        self.head_dim = head_dim
        self.mirror = mirror
        self.C = C
        self.cv_folds = cv_folds
        self.max_mixture_descriptors = max_mixture_descriptors
        self.reject_quantile = reject_quantile
        self.reject_margin = reject_margin
        self.random_state = random_state

    def params(self) -> dict[str, Any]:
        return init_params(self)

    def _check_grid(self) -> None:
        patches = len(keypoint_positions(self.size, self.bin_sizes, self.step))
        if patches > MAX_PATCHES:
            raise ValueError(f"{patches} patches a picture, more than {MAX_PATCHES}")

    # --- features --------------------------------------------------------------------------

    def featurize(self, pictures: Sequence[np.ndarray]) -> np.ndarray:
        """(n, patches·128 + hsv bins) float16: each picture's RootSIFT descriptors, flattened,
        then its HSV histogram (float16 halves what a library's pictures take in memory; the
        descriptors are unit-length square roots, well within its precision)."""
        self._check_grid()
        n_sift = len(keypoint_positions(self.size, self.bin_sizes, self.step)) * SIFT_DIM
        rows = np.empty((len(pictures), n_sift + int(np.prod(self.hsv_bins))), np.float16)
        for row, picture in zip(rows, pictures, strict=True):  # filled in place: no float64 copy
            row[:n_sift] = dense_root_sift(picture, self.size, self.bin_sizes, self.step).ravel()
            row[n_sift:] = hsv_histogram(square_thumbnail(picture, self.size), self.hsv_bins)
        return rows

    def _split(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Descriptors (n, patches, 128), a view in the rows' own type (float16: a library's
        pictures are not copied whole into float32), and HSV histograms (n, h), float32."""
        X = np.asarray(X)
        n_hsv = int(np.prod(self.hsv_bins))
        sift = X[:, :-n_hsv].reshape(len(X), -1, SIFT_DIM)
        return sift, X[:, -n_hsv:].astype(np.float32)

    def _mirrored(self, sift: np.ndarray) -> np.ndarray:
        patches, dims = mirror_order(self.size, self.bin_sizes, self.step)
        return sift[:, patches][:, :, dims]

    def _picked(self, sift: np.ndarray, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Single descriptors (k, 128) float32 and their patch numbers, picked by index into the
        pictures' patches, then (indices past the pictures) their mirror images' patches."""
        n, n_patches = sift.shape[:2]
        picture, patch = np.divmod(flat, n_patches)
        flipped = picture >= n
        order, dims = mirror_order(self.size, self.bin_sizes, self.step)
        source = np.where(flipped, order[patch], patch)
        picked = sift[picture % n, source].astype(np.float32)
        picked[flipped] = picked[flipped][:, dims]
        return picked, patch

    def _project(self, descriptors: np.ndarray) -> np.ndarray:
        return (descriptors.astype(np.float32) - self.pca_mean_) @ self.pca_components_.T

    def _local(self, sift: np.ndarray) -> np.ndarray:
        """(n, P, pca_dim [+ 2]) the descriptors in the PCA's space, with their places."""
        local = self._project(sift)
        if self.xy:
            places = keypoint_positions(self.size, self.bin_sizes, self.step) - 0.5
            local = np.concatenate([local, np.broadcast_to(places, (*local.shape[:2], 2))], axis=2)
        return local.astype(np.float32)

    def _fit_mixture(self, sift: np.ndarray, copies: int) -> None:
        """The PCA and the mixture, each on at most `max_mixture_descriptors` descriptors drawn
        from the pictures' (and, with `copies` 2, their mirror images') patches."""
        rng = np.random.default_rng(self.random_state)
        n_pictures, n_patches = sift.shape[:2]
        total = copies * n_pictures * n_patches
        if total > self.max_mixture_descriptors:
            chosen = rng.choice(total, self.max_mixture_descriptors, replace=False)
        else:
            chosen = np.arange(total)
        flat, _ = self._picked(sift, chosen)
        self.pca_mean_ = flat.mean(axis=0).astype(np.float32)
        _, _, vt = np.linalg.svd(flat - self.pca_mean_, full_matrices=False)
        self.pca_components_ = vt[: self.pca_dim].astype(np.float32)
        local = self._local_picked(sift, rng.choice(total, len(flat), replace=False))
        mixture = GaussianMixture(
            n_components=min(self.n_components, len(local)),
            covariance_type="diag",
            reg_covar=MIN_VARIANCE,
            max_iter=100,
            random_state=self.random_state,
        ).fit(local)
        self._keep_mixture(mixture)

    def _local_picked(self, sift: np.ndarray, flat: np.ndarray) -> np.ndarray:
        """(k, pca_dim [+ 2]) float32: the descriptors `_picked` by `flat`, in the PCA's space,
        with their places."""
        descriptors, patches = self._picked(sift, flat)
        local = self._project(descriptors)
        if self.xy:
            places = keypoint_positions(self.size, self.bin_sizes, self.step) - 0.5
            local = np.concatenate([local, places[patches]], axis=1)
        return local.astype(np.float32)

    def _keep_mixture(self, mixture: GaussianMixture) -> None:
        self.weights_ = mixture.weights_.astype(np.float32)
        self.means_ = mixture.means_.astype(np.float32)
        self.variances_ = mixture.covariances_.astype(np.float32)

    def _encode(self, sift: np.ndarray, hsv: np.ndarray, *, mirrored: bool = False) -> np.ndarray:
        """The normalised Fisher vector beside the weighted, square-rooted HSV histogram, 64
        pictures at a time; with `mirrored`, the mirror images' rows follow the pictures'."""
        parts = np.array_split(np.arange(len(sift)), max(1, len(sift) // 64))
        flips = (False, True) if mirrored else (False,)
        vectors = [
            power_l2(
                fisher_vectors(
                    self._local(self._mirrored(sift[part]) if flip else sift[part]),
                    self.weights_,
                    self.means_,
                    self.variances_,
                )
            )
            for flip in flips
            for part in parts
        ]
        colour = self.colour_weight * np.sqrt(hsv)
        return np.hstack([np.vstack(vectors), np.vstack([colour] * len(flips))])

    def _projected(self, encoded: np.ndarray) -> np.ndarray:
        return ((encoded - self.encoding_mean_) @ self.directions_.T) / self.scale_

    def describe(self, X: np.ndarray) -> np.ndarray:
        """(n, head_dim) the pictures in the head's space."""
        self._check_fitted()
        return self._projected(self._encode(*self._split(X)))

    # --- fitting ---------------------------------------------------------------------------

    def fit(self, X: np.ndarray, scenes: Sequence[str] | np.ndarray) -> Self:
        check_training_scenes(scenes, len(X))
        self._check_grid()
        labels = np.asarray(scenes).astype(str)
        sift, hsv = self._split(X)  # the mirror images are made from these as they are needed
        self._fit_mixture(sift, 2 if self.mirror else 1)
        encoded = self._encode(sift, hsv, mirrored=self.mirror)  # the same colours mirrored
        self.encoding_mean_, self.directions_, self.scale_ = head_space(encoded, self.head_dim)
        if not len(self.directions_):  # every training picture gave the same vector
            raise ServantError(
                "the training pictures are all one and the same to this method, so no scene "
                "can be told from another; add pictures that differ"
            )
        D = self._projected(encoded)
        rows_labels = np.concatenate([labels, labels]) if self.mirror else labels
        self.C_ = self.C if self.C is not None else self._choose_C(sift, hsv, labels)
        self.train_rows_ = D.astype(np.float32)
        self.train_scenes_ = rows_labels
        self._fit_head()
        self.novelty_head_ = SceneCentroids.fit(
            D[: len(labels)], labels, 1, self.reject_quantile, self.reject_margin, self.random_state
        )
        return self

    def _head(self, C: float) -> LogisticRegression:
        # balanced: a scene with three times the pictures must not win every doubtful picture
        return LogisticRegression(C=C, class_weight="balanced", max_iter=3000)

    def _choose_C(self, sift: np.ndarray, hsv: np.ndarray, labels: np.ndarray) -> float:
        """The regularisation whose held-out probabilities have the least log loss (the least
        regularised within one standard error of the best), held out in stratified folds of at
        most `CALIBRATION_PICTURES` pictures a place (a picture and its mirror on the same
        side). The grid's most regularised with too few pictures to fold."""
        rng = np.random.default_rng(self.random_state)
        places = [np.flatnonzero(labels == s) for s in np.unique(labels)]
        chosen = np.concatenate([rng.permutation(p)[:CALIBRATION_PICTURES] for p in places])
        pictures = labels[chosen]
        losses = settings_losses(
            pictures,
            len(C_GRID),
            lambda train, test: self._held_out(sift[chosen], hsv[chosen], pictures, train, test),
            self.cv_folds,
            self.random_state,
        )
        if losses is None:
            return C_GRID[0]
        return float(C_GRID[least_regularised_within_error(losses)])

    def _held_out(
        self,
        sift: np.ndarray,
        hsv: np.ndarray,
        labels: np.ndarray,
        train: np.ndarray,
        test: np.ndarray,
    ) -> np.ndarray:
        """(len(C_GRID), len(test), scenes) the log probabilities of the `test` pictures by a
        model learned on the `train` pictures alone, its mixture the kept one refined without
        the test pictures, for each C of the grid."""
        fold = copy.copy(self)  # shares the PCA; its own mixture, space and head
        fold._keep_mixture(self._refined_mixture(sift[train]))
        encoded = fold._encode(sift, hsv, mirrored=self.mirror)
        n = len(labels)
        rows = np.concatenate([train, train + n]) if self.mirror else train
        mean, directions, scale = head_space(encoded[rows], self.head_dim)
        scenes = len(set(labels))
        if not len(directions):  # the fold's pictures are all one: its heads know nothing
            return np.full((len(C_GRID), len(test), scenes), -np.log(scenes))
        D = ((encoded - mean) @ directions.T) / scale
        return np.array(
            [
                self._head(C).fit(D[rows], labels[rows % n]).predict_log_proba(D[test])
                for C in C_GRID
            ]
        )

    def _refined_mixture(self, sift: np.ndarray) -> GaussianMixture:
        """The kept mixture refined by `REFINE_STEPS` EM steps on some of these pictures' (and
        their mirror images') descriptors."""
        rng = np.random.default_rng(self.random_state)
        total = (2 if self.mirror else 1) * len(sift) * sift.shape[1]
        local = self._local_picked(sift, rng.choice(total, min(total, REFINE_DESCRIPTORS), False))
        weights = self.weights_.astype(np.float64)
        mixture = GaussianMixture(
            n_components=len(weights),
            covariance_type="diag",
            reg_covar=MIN_VARIANCE,
            max_iter=REFINE_STEPS,
            init_params="random_from_data",  # a cheap start, at once replaced by the kept mixture
            weights_init=weights / weights.sum(),
            means_init=self.means_,
            precisions_init=1.0 / self.variances_,
            random_state=self.random_state,
        )
        with warnings.catch_warnings():  # a few steps are meant, not convergence
            warnings.simplefilter("ignore", ConvergenceWarning)
            return mixture.fit(local)

    def _fit_head(self) -> None:
        self.head_ = self._head(self.C_).fit(self.train_rows_, self.train_scenes_)
        # the model file keeps the weights in float32: the fitted model must answer as the loaded
        self.head_.coef_ = self.head_.coef_.astype(np.float32).astype(np.float64)

    # --- using it --------------------------------------------------------------------------

    def _space(self, X: np.ndarray) -> np.ndarray:
        return self.describe(X)

    def fold_in(self, X: np.ndarray, scenes: Sequence[str]) -> Self:
        """Add pictures with confirmed scenes (a new scene too): the mixture, the head's space
        and C stay; the head is refitted on the kept training rows plus these."""
        if len(scenes) != len(X):
            raise ValueError(f"{len(X)} feature rows but {len(scenes)} scene labels")
        sift, hsv = self._split(X)
        D = self.describe(X)
        labels = np.asarray(scenes).astype(str)
        new = [D]
        if self.mirror:
            new.append(self._projected(self._encode(self._mirrored(sift), hsv)))  # few rows
        self.train_rows_ = np.vstack([self.train_rows_, *new]).astype(np.float32)
        self.train_scenes_ = np.concatenate([self.train_scenes_, *[labels] * len(new)])
        self._fit_head()
        self.novelty_head_.fold_in(D, list(scenes))
        return self

    # --- model files -----------------------------------------------------------------------

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        self._check_fitted()
        novelty, novelty_arrays = self.novelty_head_.state()
        header = {
            "params": self.params(),
            "C_": self.C_,
            "scale_": self.scale_,
            "novelty": novelty,
            "scenes": self.scenes_,
        }
        arrays = {
            "pca_mean": self.pca_mean_,
            "pca_components": self.pca_components_,
            "weights": self.weights_,
            "means": self.means_,
            "variances": self.variances_,
            "encoding_mean": self.encoding_mean_,
            "directions": self.directions_,
            "train_rows": self.train_rows_,
            # scenes as indices into the sorted scene list: no object arrays in the file
            "train_scenes": np.searchsorted(self.scenes_, self.train_scenes_),
            "coef": self.head_.coef_.astype(np.float32),
            "intercept": self.head_.intercept_,
            **{f"novelty_{k}": v for k, v in novelty_arrays.items()},
        }
        return header, arrays

    @classmethod
    def from_state(cls, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        model = cls(**header["params"])
        model._check_grid()
        model.pca_mean_ = np.asarray(arrays["pca_mean"], dtype=np.float32)
        model.pca_components_ = np.asarray(arrays["pca_components"], dtype=np.float32)
        model.weights_ = np.asarray(arrays["weights"], dtype=np.float32)
        model.means_ = np.asarray(arrays["means"], dtype=np.float32)
        model.variances_ = np.asarray(arrays["variances"], dtype=np.float32)
        if not (np.all(model.weights_ > 0) and np.all(model.variances_ > 0)):
            raise ValueError("its mixture has a weight or variance that is not above zero")
        model.encoding_mean_ = np.asarray(arrays["encoding_mean"], dtype=np.float32)
        model.directions_ = np.asarray(arrays["directions"], dtype=np.float32)
        model.scale_ = float(header["scale_"])
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
