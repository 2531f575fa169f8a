"""`kmeans` for the motion and ambient senses: per-scene K-Means over a window's few features.

A window of readings (n, channels) becomes a short vector (`features.motion`, `features.ambient`),
standardised and, with 20 training windows a scene or more, projected by shrunk LDA
(`discriminant`). Each scene's vectors are a few K-Means centroids with their spreads
(`SceneCentroids`): probabilities from distances, a window far from every centroid unknown. One
factor on all spreads minimises held-out log loss (stratified folds; 1 below three rows a scene).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar, Self

import numpy as np
from sklearn.model_selection import StratifiedKFold

from servant_core.capture.sensors import AMBIENT_CHANNELS, AMBIENT_RATE, IMU_CHANNELS, IMU_RATE
from servant_core.features.ambient import ambient_features
from servant_core.features.motion import motion_features
from servant_core.recognisers.base import UNKNOWN, init_params, scene_probabilities
from servant_core.recognisers.centroids import CentroidRecogniser

CALIBRATION_FOLDS = 3
# never sharper than half the spreads measured on the training rows: on scenes it separates
# perfectly, the held-out loss would keep falling toward certainty
SPREAD_FACTORS = np.geomspace(0.5, 16.0, 31)


class SensorCentroidRecogniser(CentroidRecogniser):
    """The shared part; subclasses name their sense, channels, rate and feature function."""

    channels: ClassVar[tuple[str, ...]]
    default_rate: ClassVar[int]
    # the features are few: a whitened novelty space adds nothing to plain distances
    whitened_novelty = False

    def __init__(
        self,
        *,
        rate: int | None = None,
        window_seconds: float = 5.0,
        clusters_per_scene: int = 2,
        spread_shrinkage: float = 0.5,
        discriminant: bool = True,
        reject_quantile: float = 0.95,
        reject_margin: float = 1.5,
        random_state: int | None = 0,
    ) -> None:
        # rate: readings a second of the windows `featurize` takes (None: the sensor's own)
        self.rate = self.default_rate if rate is None else rate
        self.window_seconds = window_seconds
        self.clusters_per_scene = clusters_per_scene
        self.spread_shrinkage = spread_shrinkage
        self.discriminant = discriminant
        self.reject_quantile = reject_quantile
        self.reject_margin = reject_margin
        self.random_state = random_state

    def params(self) -> dict[str, Any]:
        return init_params(self)

    def featurize(self, items: Sequence[np.ndarray]) -> np.ndarray:
        """(n, features) of a list of (samples, channels) windows at `self.rate`."""
        return np.stack([self.window_features(np.asarray(w)) for w in items])

    def window_features(self, window: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _fit_codebooks(self, X: np.ndarray) -> None:
        pass  # the features are fixed: nothing to learn before the centroids

    def describe(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(X, dtype=np.float64)

    def _codebook_arrays(self) -> dict[str, np.ndarray]:
        return {"spread_factor": np.array([self.spread_factor_])}

    def _load_codebook_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        factor = np.asarray(arrays["spread_factor"], dtype=np.float64)
        if factor.shape != (1,) or not factor[0] > 0:
            raise ValueError("spread_factor must be one number above zero")
        self.spread_factor_ = float(factor[0])

    def fit(self, X: np.ndarray, scenes: Sequence[str] | np.ndarray) -> Self:
        X = np.asarray(X, dtype=np.float64)
        self.spread_factor_ = held_out_spread_factor(self, X, np.asarray(scenes))
        return super().fit(X, scenes)

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        return self._proba(self.descriptors(X))

    def _proba(self, D: np.ndarray) -> np.ndarray:
        head = self.head_
        return scene_probabilities(
            head.distances(D), head.spreads * self.spread_factor_, head.cluster_scene, head.scenes
        )

    def predict(self, X: np.ndarray) -> np.ndarray:
        D = self.descriptors(X)
        names = np.asarray(self.head_.scenes, dtype=object)[np.argmax(self._proba(D), axis=1)]
        names[self.head_.is_unknown(D)] = UNKNOWN
        return names.astype(str)


def held_out_spread_factor(
    model: SensorCentroidRecogniser, X: np.ndarray, scenes: np.ndarray
) -> float:
    """The factor on the spreads that minimises the log-loss of rows held out of the fit."""
    _, counts = np.unique(scenes, return_counts=True)
    if counts.min() < CALIBRATION_FOLDS:
        return 1.0
    folds = StratifiedKFold(CALIBRATION_FOLDS, shuffle=True, random_state=model.random_state)
    losses = np.zeros(len(SPREAD_FACTORS))
    for train, test in folds.split(X, scenes):
        inner = type(model)(**model.params())
        inner.spread_factor_ = 1.0
        CentroidRecogniser.fit(inner, X[train], scenes[train])
        D = inner.descriptors(X[test])
        head = inner.head_
        truth = np.searchsorted(head.scenes, scenes[test])
        for i, factor in enumerate(SPREAD_FACTORS):
            proba = scene_probabilities(
                head.distances(D), head.spreads * factor, head.cluster_scene, head.scenes
            )
            losses[i] -= np.sum(np.log(np.maximum(proba[np.arange(len(test)), truth], 1e-12)))
    return float(SPREAD_FACTORS[int(np.argmin(losses))])


class MotionRecogniser(SensorCentroidRecogniser):
    method: ClassVar[str] = "kmeans"
    sense: ClassVar[str] = "motion"
    channels = IMU_CHANNELS
    default_rate = IMU_RATE

    def window_features(self, window: np.ndarray) -> np.ndarray:
        return motion_features(window, self.rate)


class AmbientRecogniser(SensorCentroidRecogniser):
    method: ClassVar[str] = "kmeans"
    sense: ClassVar[str] = "ambient"
    channels = AMBIENT_CHANNELS
    default_rate = AMBIENT_RATE

    def window_features(self, window: np.ndarray) -> np.ndarray:
        return ambient_features(window, self.rate)
