"""The paper's recognisers: K-Means with one cluster per scene, clusters named by majority.

Acoustic: raw FFT vectors (frequency array + amplitude array), confidence eq. 1,
C = 100 − ‖A − B‖ / 10000. Visual: the dominant colours of a picture, confidence eq. 2,
C = 100 − ‖A − B‖. A is the test point, B its nearest centroid. Both formulas are kept as the
paper wrote them: they can go below zero for a point far from every centroid.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar, Self

import numpy as np
from scipy.spatial.distance import cdist
from sklearn.cluster import KMeans
from sklearn.exceptions import NotFittedError

from servant_core.audio import DEFAULT_RATE, DEFAULT_WINDOW_SECONDS
from servant_core.features.palette import DEFAULT_COLOURS, dominant_colours
from servant_core.features.paper_fft import paper_fft_vectors
from servant_core.recognisers.base import (
    UNKNOWN,
    ClusterLabels,
    TaughtPlacesOnly,
    check_training_scenes,
    cluster_spreads,
    init_params,
    label_clusters,
    scene_probabilities,
)


def paper_confidence(distance: np.ndarray | float, divisor: float) -> np.ndarray:
    """Eq. 1 (divisor 10000, acoustic) and eq. 2 (divisor 1, visual): 100 − ‖A − B‖ / divisor."""
    return 100.0 - np.asarray(distance, dtype=float) / divisor


class KMeansSceneRecogniser(TaughtPlacesOnly):
    """K-Means with K = number of scenes over featurized rows; shared by both paper senses."""

    method: ClassVar[str] = "paper"
    sense: ClassVar[str]
    confidence_divisor: ClassVar[float]
    confidence_unit: ClassVar[str]  # the paper's equation: not a percentage

    random_state: int | None
    n_init: int

    def fit(self, X: np.ndarray, scenes: Sequence[str] | np.ndarray) -> Self:
        self.scenes_ = check_training_scenes(scenes, len(X))
        kmeans = KMeans(
            n_clusters=len(self.scenes_),
            n_init=self.n_init,
            random_state=self.random_state,
            # centre X in place and put it back (float rounding aside) instead of copying it
            copy_x=False,
        )
        clusters = kmeans.fit_predict(X)
        self.centres_ = kmeans.cluster_centers_.astype(np.float32)
        self.labels_: ClusterLabels = label_clusters(clusters, scenes, len(self.scenes_))
        self.spreads_ = cluster_spreads(np.asarray(X, dtype=np.float32), clusters, self.centres_)
        return self

    def _check_fitted(self) -> None:
        if not hasattr(self, "centres_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit first")

    def distances(self, X: np.ndarray) -> np.ndarray:
        """(n, K) Euclidean distances from each row to each centroid."""
        self._check_fitted()
        X = np.asarray(X, dtype=np.float32)
        # scipy's cdist is ~10x faster than sklearn's float32 path for a few long rows (the live
        # case); chunks keep its float64 copy of X small when a whole test set is scored
        chunk = 64
        return np.vstack(
            [cdist(X[i : i + chunk], self.centres_) for i in range(0, max(len(X), 1), chunk)]
        )

    def nearest(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(cluster index, distance) of each row's nearest centroid: K-Means' `predict`."""
        d = self.distances(X)
        cluster = np.argmin(d, axis=1)
        return cluster, d[np.arange(len(d)), cluster]

    def predict(self, X: np.ndarray) -> np.ndarray:
        cluster, _ = self.nearest(X)
        names = [s if s is not None else UNKNOWN for s in self.labels_.cluster_scene]
        return np.array(names, dtype=object)[cluster].astype(str)

    def confidence(self, X: np.ndarray) -> np.ndarray:
        _, distance = self.nearest(X)
        return paper_confidence(distance, self.confidence_divisor)

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        return scene_probabilities(
            self.distances(X), self.spreads_, self.labels_.cluster_scene, self.scenes_
        )

    def fit_warnings(self) -> list[str]:
        """Clusters without a majority scene, scenes that own no cluster (`ClusterLabels`)."""
        return self.labels_.warnings()

    def params(self) -> dict[str, Any]:
        raise NotImplementedError

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        self._check_fitted()
        header = {
            "params": self.params(),
            "scenes": self.scenes_,
            "cluster_scene": self.labels_.cluster_scene,
        }
        return header, {"centres": self.centres_, "spreads": self.spreads_}

    @classmethod
    def from_state(cls, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        model = cls(**header["params"])
        model.scenes_ = list(header["scenes"])
        model.centres_ = np.asarray(arrays["centres"], dtype=np.float32)
        model.spreads_ = np.asarray(arrays["spreads"], dtype=float)
        cluster_scene = list(header["cluster_scene"])
        model.labels_ = ClusterLabels(
            cluster_scene,
            unowned_scenes=sorted(set(model.scenes_) - {s for s in cluster_scene if s}),
        )
        return model


class PaperAcousticRecogniser(KMeansSceneRecogniser):
    sense = "audio"
    confidence_divisor = 10000.0
    confidence_unit = "eq. 1"

    def __init__(
        self,
        *,
        rate: int = DEFAULT_RATE,
        window_seconds: float = DEFAULT_WINDOW_SECONDS,
        random_state: int | None = 0,
        n_init: int = 10,
    ) -> None:
        self.rate = rate
        self.window_seconds = window_seconds
        self.random_state = random_state
        self.n_init = n_init

    def featurize(self, windows: np.ndarray) -> np.ndarray:
        return paper_fft_vectors(windows, self.rate)

    def params(self) -> dict[str, Any]:
        return init_params(self)


class PaperVisualRecogniser(KMeansSceneRecogniser):
    """Feature: the picture's dominant colours (RGB 0–255), largest share first, concatenated."""

    sense = "image"
    confidence_divisor = 1.0
    confidence_unit = "eq. 2"

    def __init__(
        self, *, n_colours: int = DEFAULT_COLOURS, random_state: int | None = 0, n_init: int = 10
    ) -> None:
        self.n_colours = n_colours
        self.random_state = random_state
        self.n_init = n_init

    def featurize(self, pictures: Sequence[np.ndarray]) -> np.ndarray:
        rows = [dominant_colours(p, self.n_colours)[0].ravel() for p in pictures]
        return np.array(rows, dtype=np.float32).reshape(len(rows), 3 * self.n_colours)

    def matched_palette(self, X: np.ndarray) -> np.ndarray:
        """The training palette (nearest centroid as k RGB colours) each row matched."""
        cluster, _ = self.nearest(X)
        return (
            np.clip(np.rint(self.centres_[cluster]), 0, 255)
            .astype(np.uint8)
            .reshape(len(cluster), self.n_colours, 3)
        )

    def params(self) -> dict[str, Any]:
        return init_params(self)
