"""Per-scene K-Means centroids over window or picture descriptors, with an open set.

Each scene's training descriptors are clustered by K-Means into a few centroids, each with its
own spread. A row's per-scene probabilities come from its distances to the centroids scaled by
their spreads (`scene_probabilities`); a row farther than `reject_distance` spreads from every
centroid is `UNKNOWN`, not a forced guess. A confirmed label folds in without refitting: the
nearest centroid of that scene moves toward the row as a running mean, or a new scene gets one.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Self

import numpy as np
from sklearn.cluster import KMeans
from sklearn.covariance import LedoitWolf
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis
from sklearn.exceptions import NotFittedError
from sklearn.metrics.pairwise import euclidean_distances

from servant_core.recognisers.base import (
    PERCENT,
    UNKNOWN,
    TaughtPlacesOnly,
    check_training_scenes,
    cluster_spreads,
    scene_probabilities,
)

MIN_CLUSTER_ROWS = 8
# The LDA step needs this many training rows of every scene. With fewer (a first teach session:
# a handful of pictures a scene) it separates the training rows perfectly, leaving no spread to
# judge a new row by, and every new picture of a taught place would be "unknown".
MIN_DISCRIMINANT_ROWS = 20


@dataclass
class SceneCentroids:
    """Fitted centroids: `centres` (K, d), `cluster_scene` (K,), `spreads` and `counts` (K,)."""

    scenes: list[str]
    centres: np.ndarray
    cluster_scene: list[str]
    spreads: np.ndarray
    counts: np.ndarray
    reject_distance: float

    @classmethod
    def fit(
        cls,
        D: np.ndarray,
        scenes: Sequence[str] | np.ndarray,
        clusters_per_scene: int,
        reject_quantile: float,
        reject_margin: float,
        random_state: int | None,
        spread_shrinkage: float = 0.0,
    ) -> SceneCentroids:
        """Cluster each scene's rows; calibrate the rejection on the training rows themselves.

        `reject_distance` is the `reject_quantile` of the training rows' distances to their own
        centroid, in units of that centroid's spread, times `reject_margin`. `spread_shrinkage`
        pulls each spread toward the median spread (geometrically; 0 keeps each cluster's own, 1
        makes them all equal).
        """
        scenes_arr = np.asarray(scenes)
        names = sorted(set(scenes_arr.tolist()))
        centres: list[np.ndarray] = []
        owner: list[str] = []
        assigned = np.empty(len(D), dtype=int)
        for scene in names:
            rows = np.flatnonzero(scenes_arr == scene)
            # a spread measured on a handful of rows is noise: each cluster gets enough of them
            k = max(1, min(clusters_per_scene, len(rows) // MIN_CLUSTER_ROWS))
            kmeans = KMeans(n_clusters=k, n_init=3, random_state=random_state).fit(D[rows])
            assigned[rows] = len(centres) + kmeans.labels_
            centres += list(kmeans.cluster_centers_)
            owner += [scene] * k
        centre_arr = np.asarray(centres, dtype=np.float64)
        spreads = cluster_spreads(D, assigned, centre_arr)
        spreads = spreads ** (1 - spread_shrinkage) * np.median(spreads) ** spread_shrinkage
        counts = np.bincount(assigned, minlength=len(centre_arr)).astype(np.float64)
        own = np.linalg.norm(D - centre_arr[assigned], axis=1) / spreads[assigned]
        # Only rows whose cluster's spread was measured (two members or more) say how far a
        # known place strays; with too few of them (a first teach session: a window or two a
        # scene) nothing can be called unknown yet, rather than everything.
        measured = counts[assigned] >= 2
        if measured.sum() < MIN_CLUSTER_ROWS:
            reject = float("inf")
        else:
            reject = float(np.quantile(own[measured], reject_quantile) * reject_margin)
        return cls(names, centre_arr, owner, spreads, counts, reject)

    def distances(self, D: np.ndarray) -> np.ndarray:
        return euclidean_distances(D, self.centres)

    def proba(self, D: np.ndarray) -> np.ndarray:
        return scene_probabilities(self.distances(D), self.spreads, self.cluster_scene, self.scenes)

    def nearest_scaled(self, D: np.ndarray) -> np.ndarray:
        """Each row's distance to its nearest centroid, in units of that centroid's spread."""
        return np.min(self.distances(D) / self.spreads[None, :], axis=1)

    def is_unknown(self, D: np.ndarray) -> np.ndarray:
        return self.nearest_scaled(D) > self.reject_distance

    def predict(self, D: np.ndarray, unknown: np.ndarray | None = None) -> np.ndarray:
        """The most probable scene of each row, `UNKNOWN` where `unknown` (by default: where
        the row is too far from every centroid)."""
        probs = self.proba(D)
        names = np.asarray(self.scenes, dtype=object)[np.argmax(probs, axis=1)]
        names[self.is_unknown(D) if unknown is None else unknown] = UNKNOWN
        return names.astype(str)

    def fold_in(self, D: np.ndarray, scenes: Sequence[str]) -> None:
        """Add confirmed rows: a known scene's nearest centroid takes a running-mean step toward
        each row (its spread updated the same way); an unknown scene gets a new centroid."""
        for row, scene in zip(D, scenes, strict=True):
            own = [c for c, s in enumerate(self.cluster_scene) if s == scene]
            if not own:
                self.scenes = sorted([*self.scenes, scene])
                self.centres = np.vstack([self.centres, row])
                self.cluster_scene.append(scene)
                self.spreads = np.append(self.spreads, np.median(self.spreads))
                self.counts = np.append(self.counts, 1.0)
                continue
            c = own[int(np.argmin(np.linalg.norm(self.centres[own] - row, axis=1)))]
            self.counts[c] += 1
            step = 1.0 / self.counts[c]
            gap = float(np.sum((row - self.centres[c]) ** 2))
            self.spreads[c] = np.sqrt((1 - step) * self.spreads[c] ** 2 + step * (1 - step) * gap)
            self.centres[c] += step * (row - self.centres[c])

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        header = {
            "scenes": self.scenes,
            "cluster_scene": self.cluster_scene,
            "reject_distance": self.reject_distance,
        }
        arrays = {"centres": self.centres, "spreads": self.spreads, "counts": self.counts}
        return header, arrays

    @classmethod
    def from_state(cls, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> SceneCentroids:
        return cls(
            list(header["scenes"]),
            np.asarray(arrays["centres"], dtype=np.float64),
            list(header["cluster_scene"]),
            np.asarray(arrays["spreads"], dtype=np.float64),
            np.asarray(arrays["counts"], dtype=np.float64),
            float(header["reject_distance"]),
        )


class CentroidRecogniser(TaughtPlacesOnly):
    """A recogniser whose learned part is codebooks (subclass) plus a `SceneCentroids` head.

    Subclasses define `featurize`, `params()`, `_fit_codebooks(X)` (learn from featurized
    training rows, store attributes ending in `_`), `describe(X)` (featurized rows to fixed
    descriptors) and `_codebook_arrays()` / `_load_codebook_arrays(arrays)`.
    """

    method: ClassVar[str]
    sense: ClassVar[str]
    confidence_unit: ClassVar[str] = PERCENT
    folds_in: ClassVar[bool] = True

    clusters_per_scene: int
    spread_shrinkage: float
    discriminant: bool
    whitened_novelty: bool
    reject_quantile: float
    reject_margin: float
    random_state: int | None

    def params(self) -> dict[str, Any]:
        raise NotImplementedError

    def describe(self, X: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _fit_codebooks(self, X: np.ndarray) -> None:
        raise NotImplementedError

    def _codebook_arrays(self) -> dict[str, np.ndarray]:
        raise NotImplementedError

    def _load_codebook_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        raise NotImplementedError

    def fit(self, X: np.ndarray, scenes: Sequence[str] | np.ndarray) -> Self:
        check_training_scenes(scenes, len(X))
        self._fit_codebooks(X)
        D = self.describe(X)
        self.mean_ = D.mean(axis=0)
        # Codewords no training row uses have no spread; they must not divide by zero.
        self.scale_ = np.where(D.std(axis=0) > 1e-9, D.std(axis=0), 1.0)
        D = self._standardise(D)
        if self.discriminant:
            # A light linear step before the centroids: the directions that best separate the
            # training scenes (shrunk LDA, stable with fewer rows than dimensions). Below
            # MIN_DISCRIMINANT_ROWS rows of a scene the descriptors stay as they are.
            self.projection_ = np.eye(D.shape[1])
            _, counts = np.unique(np.asarray(scenes), return_counts=True)
            if counts.min() >= MIN_DISCRIMINANT_ROWS:
                lda = LinearDiscriminantAnalysis(solver="eigen", shrinkage="auto")
                # rows that are all alike (plain-colour pictures) leave no within-scene
                # spread to factor: the descriptors then stay as they are
                with contextlib.suppress(np.linalg.LinAlgError):
                    lda.fit(D, scenes)
                    self.projection_ = lda.scalings_[:, : len(lda.classes_) - 1]
            D = self._project(D)
        self.head_ = self._fit_head(D, scenes)
        if self.whitened_novelty:
            # "Is this a place I know?" is asked in a space whitened by the spread of windows
            # within a scene: a new place usually differs along directions in which a known
            # place hardly varies, where plain distances would not notice it.
            scenes_arr = np.asarray(scenes)
            residuals = np.vstack(
                [D[scenes_arr == s] - D[scenes_arr == s].mean(axis=0) for s in self.head_.scenes]
            )
            values, vectors = np.linalg.eigh(LedoitWolf().fit(residuals).covariance_)
            self.whitening_ = vectors / np.sqrt(np.maximum(values, 1e-12))
            self.novelty_head_ = self._fit_head(D @ self.whitening_, scenes)
        return self

    def _fit_head(self, D: np.ndarray, scenes: Sequence[str] | np.ndarray) -> SceneCentroids:
        return SceneCentroids.fit(
            D,
            scenes,
            self.clusters_per_scene,
            self.reject_quantile,
            self.reject_margin,
            self.random_state,
            self.spread_shrinkage,
        )

    def _novelty_head(self, D: np.ndarray) -> tuple[SceneCentroids, np.ndarray]:
        """The head that decides "unknown", and the rows in its space."""
        if self.whitened_novelty:
            return self.novelty_head_, D @ self.whitening_
        return self.head_, D

    @property
    def scenes_(self) -> list[str]:
        self._check_fitted()
        return self.head_.scenes

    def _check_fitted(self) -> None:
        if not hasattr(self, "head_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit first")

    def _standardise(self, D: np.ndarray) -> np.ndarray:
        return (D - self.mean_) / self.scale_

    def _project(self, D: np.ndarray) -> np.ndarray:
        if not self.discriminant:
            return D
        return D @ self.projection_

    def descriptors(self, X: np.ndarray) -> np.ndarray:
        """Standardised (and, when `discriminant`, projected) descriptors: the space the scene
        centroids live in."""
        self._check_fitted()
        return self._project(self._standardise(self.describe(X)))

    def predict(self, X: np.ndarray) -> np.ndarray:
        D = self.descriptors(X)
        head, rows = self._novelty_head(D)
        return self.head_.predict(D, head.is_unknown(rows))

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        D = self.descriptors(X)
        return self.head_.proba(D)

    def confidence(self, X: np.ndarray) -> np.ndarray:
        """The probability of the most likely scene, in percent."""
        return 100.0 * np.max(self.predict_proba(X), axis=1)

    def novelty(self, X: np.ndarray) -> np.ndarray:
        """Distance to the nearest centroid in its spreads, divided by the rejection distance:
        above 1 a row is unknown."""
        head, rows = self._novelty_head(self.descriptors(X))
        return head.nearest_scaled(rows) / head.reject_distance

    def fold_in(self, X: np.ndarray, scenes: Sequence[str]) -> Self:
        """Fold rows with confirmed labels into the model without refitting (codebooks stay)."""
        if len(scenes) != len(X):
            raise ValueError(f"{len(X)} feature rows but {len(scenes)} scene labels")
        D = self.descriptors(X)
        self.head_.fold_in(D, scenes)
        if self.whitened_novelty:
            self.novelty_head_.fold_in(D @ self.whitening_, scenes)
        return self

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        self._check_fitted()
        head, head_arrays = self.head_.state()
        arrays = {"mean": self.mean_, "scale": self.scale_, **head_arrays}
        if self.discriminant:
            arrays["projection"] = self.projection_
        arrays.update(self._codebook_arrays())
        header = {"params": self.params(), **head}
        if self.whitened_novelty:
            novelty, novelty_arrays = self.novelty_head_.state()
            header["novelty"] = novelty
            arrays["whitening"] = self.whitening_
            arrays.update({f"novelty_{k}": v for k, v in novelty_arrays.items()})
        return header, arrays

    @classmethod
    def from_state(cls, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        model = cls(**header["params"])
        model.mean_ = np.asarray(arrays["mean"], dtype=np.float64)
        model.scale_ = np.asarray(arrays["scale"], dtype=np.float64)
        if model.discriminant:
            model.projection_ = np.asarray(arrays["projection"], dtype=np.float64)
        model.head_ = SceneCentroids.from_state(header, arrays)
        if model.whitened_novelty:
            model.whitening_ = np.asarray(arrays["whitening"], dtype=np.float64)
            prefixed = {
                k[len("novelty_") :]: v for k, v in arrays.items() if k.startswith("novelty_")
            }
            model.novelty_head_ = SceneCentroids.from_state(header["novelty"], prefixed)
        model._load_codebook_arrays(arrays)
        return model


def spherical_kmeans(
    rows: np.ndarray, n_codewords: int, max_rows: int, random_state: int | None
) -> np.ndarray:
    """Unit-length codewords from K-Means on unit-length rows (a subsample of at most `max_rows`).

    On the unit sphere the nearest centre in Euclidean distance is the one of largest cosine,
    so K-Means followed by renormalising its centres is spherical K-Means' usual approximation.
    """
    rng = np.random.default_rng(random_state)
    if len(rows) > max_rows:
        rows = rows[rng.choice(len(rows), max_rows, replace=False)]
    k = min(n_codewords, len(rows))
    kmeans = KMeans(n_clusters=k, n_init=1, random_state=random_state).fit(rows)
    centres = kmeans.cluster_centers_
    return (centres / np.maximum(np.linalg.norm(centres, axis=1, keepdims=True), 1e-12)).astype(
        np.float32
    )


def unit_rows(X: np.ndarray) -> np.ndarray:
    """Rows scaled to unit length (all-zero rows stay zero)."""
    return X / np.maximum(np.linalg.norm(X, axis=-1, keepdims=True), 1e-12)


def codeword_histograms(assigned: np.ndarray, n_codewords: int) -> np.ndarray:
    """(n, n_codewords) share of each codeword in each row of an (n, m) assignment array."""
    n, m = assigned.shape
    flat = (assigned + n_codewords * np.arange(n)[:, None]).ravel()
    return np.bincount(flat, minlength=n * n_codewords).reshape(n, n_codewords) / max(m, 1)
