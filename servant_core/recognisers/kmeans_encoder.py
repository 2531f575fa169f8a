"""`kmeans-encoder`: K-Means features with a discriminative head (Coates & Ng's single layer).

A 5 s window becomes log-mel frames over 60 Hz–10.5 kHz, mean level removed (`features.logmel`);
per band the mean, spread and frame-to-frame change, and the frames' triangle encodings
max(0, mean(z) − z_k) against K-Means codebooks (one per ensemble member), pooled over the window.
A multinomial logistic head over the standardised statistics and encodings (the encodings scaled
by `encoding_weight`; training windows also seen through fixed equalisations) has one class per
visit of a place plus `<elsewhere>`, learned from the universal background
(`recognisers.background`). `predict_proba`: the share among taught places, a place scored by its
likeliest visit (mixed with a head of one class a place: `place_share`, `birdnet`'s);
`open_proba`: the probability of a place and not somewhere else (its visits summed). Both are
softmax(logits / `temperature`). A window farther than the rejection distance
from every place's centroid (`SceneCentroids`) is `UNKNOWN`. `fit` takes each window's visit
(`visits`; `library.visits_of`); without them a place is one visit."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np
from sklearn.cluster import KMeans
from sklearn.exceptions import NotFittedError

from servant_core.features.logmel import DEFAULT_FMAX, DEFAULT_FMIN, log_mel_windows
from servant_core.recognisers.background import (
    BACKGROUND_PATH,
    FRAME_KEYS,
    Background,
    load_background,
)
from servant_core.recognisers.base import PERCENT, check_training_scenes, init_params
from servant_core.recognisers.centroids import SceneCentroids, unit_rows
from servant_core.recognisers.encoder_features import (
    eq_curves,
    equalised,
    frame_statistics,
    triangle_encoding,
    window_crops,
)
from servant_core.recognisers.linear_head import LinearHeadAnswers
from servant_core.recognisers.visit_head import (
    VisitHead,
    fit_visit_head,
    place_proba,
    softmax_proba,
)

ENCODER_RATE = 22050
SCALE_FLOOR = 0.1
NOVELTY_SHRINKAGE = 0.0
# The softening of the head's probabilities (module docstring, 7): chosen by the log loss of the
# parameter search's folds inside the training data (bench/kmeans_encoder_temperature.py).
TEMPERATURE = 2.0
# The scale of the encodings' columns against the frame statistics' in the head (module
# docstring, 4): chosen by the parameter search's folds inside the training data.
ENCODING_WEIGHT = 0.1
# How much the background weighs in the head against one taught place (module docstring, 7).
ELSEWHERE_WEIGHT = 1.0
# Parameters a model file saved before they existed lacks, at the value that reproduces how that
# model behaved (not today's default): its probabilities stay as they were.
LEGACY_PARAMS: dict[str, Any] = {
    "temperature": 1.0,
    "encoding_weight": 1.0,
    "background": False,
}


class KMeansEncoderAcousticRecogniser(LinearHeadAnswers):
    method: ClassVar[str] = "kmeans-encoder"
    sense: ClassVar[str] = "audio"
    confidence_unit: ClassVar[str] = PERCENT
    # its head has a class a visit (birdnet's and effnet's through it): `fit` takes `visits`
    learns_visits: ClassVar[bool] = True
    # the parameters an older model file lacks, at the values it was made with (LEGACY_PARAMS)
    legacy_params: ClassVar[dict[str, Any]] = LEGACY_PARAMS
    # the universal background this featurizer's windows are kept in (`recognisers.background`)
    background_path: ClassVar[Path] = BACKGROUND_PATH
    # the featurizer parameters a background file must share with the model to be used
    background_keys: ClassVar[tuple[str, ...]] = FRAME_KEYS
    # the nearest-taught-window check of `_unlike_taught` (None: none; `birdnet` has one)
    accept_cosine: float | None = None
    # each place's acceptance from the background instead (`_acceptance`; `birdnet` offers it)
    calibrated_accept: bool = False
    # the share of a head with one class a place in `predict_proba` (`_proba`; `birdnet` has one)
    place_share: float = 0.0
    # the head's penalty (None: chosen in `fit` by `_penalty`, which `effnet` does)
    C: float | None

    def __init__(
        self,
        *,
        rate: int = ENCODER_RATE,
        window_seconds: float = 5.0,
        n_mels: int = 64,
        frame_seconds: float = 0.046,
        fmin: float = DEFAULT_FMIN,
        fmax: float = DEFAULT_FMAX,
        n_codewords: int = 128,
        n_codebooks: int = 3,
        C: float = 2.0,
        augment: int = 2,
        crops: int = 4,
        crop_fraction: float = 0.25,
        eq_strength: float = 0.45,
        max_codebook_frames: int = 20000,
        reject_quantile: float = 0.95,
        reject_margin: float = 1.7,
        temperature: float = TEMPERATURE,
        encoding_weight: float = ENCODING_WEIGHT,
        background: bool = True,
        elsewhere_weight: float = ELSEWHERE_WEIGHT,
        background_exclude: Sequence[str] = (),
        random_state: int | None = 0,
    ) -> None:
        self.rate = rate
        self.window_seconds = window_seconds
        self.n_mels = n_mels
        self.frame_seconds = frame_seconds
        self.fmin = fmin
        self.fmax = fmax
        self.n_codewords = n_codewords
        self.n_codebooks = n_codebooks
        self.C = C
        self.augment = augment
        self.crops = crops
        self.crop_fraction = crop_fraction
        self.eq_strength = eq_strength
        self.max_codebook_frames = max_codebook_frames
        self.reject_quantile = reject_quantile
        self.reject_margin = reject_margin
        self.temperature = temperature
        self.encoding_weight = encoding_weight
        self.background = background
        self.elsewhere_weight = elsewhere_weight
        self.background_exclude = background_exclude
        self.random_state = random_state

    def params(self) -> dict[str, Any]:
        """What a model file keeps: every parameter but `background_exclude`, which says only
        which recordings the fit kept out of the background."""
        params = init_params(self)
        del params["background_exclude"]
        return params

    def background_params(self) -> dict[str, Any]:
        """What the background file is checked against (`background_keys`)."""
        return {k: getattr(self, k) for k in self.background_keys}

    def featurize(self, windows: np.ndarray) -> np.ndarray:
        """(n, frames, n_mels) level-free log-mel frames of (n, samples) windows at `rate`."""
        return log_mel_windows(
            windows, self.rate, self.frame_seconds, self.n_mels, self.fmin, self.fmax
        )

    # -- learning ---------------------------------------------------------------------------

    def fit(
        self,
        X: np.ndarray,
        scenes: Sequence[str] | np.ndarray,
        visits: Sequence[Any] | np.ndarray | None = None,
    ) -> Self:
        """Learn the places of windows `X`; `visits` (any labels) say which visit each window
        comes from (module docstring, 8); None: every place is one visit."""
        self._check_fit(X, scenes, visits)
        if not self.encoding_weight >= 0:
            raise ValueError(f"encoding_weight must be 0 or above, not {self.encoding_weight!r}")
        X = np.asarray(X, dtype=np.float32)
        scenes_arr = np.asarray(scenes).astype(str)
        rng = np.random.default_rng(self.random_state)
        curves = eq_curves(X.shape[-1], self.eq_strength, self.augment)
        views = [X] + [equalised(X, curve) for curve in curves]
        frames = np.concatenate(views)
        flat = frames.reshape(-1, frames.shape[-1])
        sample = flat[rng.choice(len(flat), min(len(flat), self.max_codebook_frames), False)]
        self.frame_mean_ = sample.mean(axis=0, dtype=np.float32)
        self.frame_scale_ = (sample.std(axis=0) + 1e-6).astype(np.float32)
        standard = (sample - self.frame_mean_) / self.frame_scale_
        seeds = rng.integers(0, 2**31 - 1, self.n_codebooks)
        k = min(self.n_codewords, len(standard))
        self.codebooks_ = np.stack(
            [
                KMeans(k, n_init=1, random_state=int(seed)).fit(standard).cluster_centers_
                for seed in seeds
            ]
        ).astype(np.float32)
        parts = [frames, *window_crops(X, self.crops, self.crop_fraction)]
        D = np.vstack([self.describe(part) for part in parts]).astype(np.float64)
        # A codeword almost no training frame comes near has next to no spread; unfloored, a new
        # place that does come near it would sit thousands of spreads away on that one column.
        self._fit_scale(D)
        self.train_descriptors_ = self._standardise(D)
        self.background_descriptors_ = self._background_descriptors()
        copies = len(D) // len(X)
        self.train_scenes_ = np.tile(scenes_arr, copies)
        visit_arr = scenes_arr if visits is None else np.asarray(visits).astype(str)
        self.train_visits_ = np.tile(visit_arr, copies)
        self.train_derived_ = np.arange(len(D)) >= len(X)
        self.C_ = self._penalty()
        self._fit_heads()
        return self

    def _penalty(self) -> float:
        """The head's C: the parameter (`effnet` chooses its own from the taught pictures)."""
        if self.C is None:
            raise ValueError(f"{self.method} needs a number for C")
        return float(self.C)

    def _check_fit(
        self, X: np.ndarray, scenes: Sequence[str] | np.ndarray, visits: Any | None
    ) -> None:
        check_training_scenes(scenes, len(X))
        if visits is not None and len(visits) != len(X):
            raise ValueError(f"{len(X)} feature rows but {len(visits)} visit labels")
        if not self.temperature > 0:
            raise ValueError(f"temperature must be above 0, not {self.temperature!r}")
        if not 0 <= self.place_share <= 1:
            raise ValueError(f"place_share must be from 0 to 1, not {self.place_share!r}")

    def _fit_scale(self, D: np.ndarray) -> None:
        """Each descriptor column's mean and spread over `D`, the spread floored."""
        spread = D.std(axis=0)
        self.descriptor_mean_ = D.mean(axis=0)
        self.descriptor_scale_ = np.maximum(spread, SCALE_FLOOR * np.median(spread) + 1e-12)

    def _background(self) -> Background | None:
        """This featurizer's windows of the universal background, without the recordings in
        `background_exclude` (None: the parameter is off, no background file, or it was made
        with another featurizer)."""
        if not self.background:
            return None
        return load_background(
            self.background_params(), self.background_exclude, self.background_path
        )

    def _background_descriptors(self) -> np.ndarray:
        """The universal background through this model's codebooks (empty without one)."""
        found = self._background()
        if found is None or not len(found.frames):
            return np.empty((0, self.train_descriptors_.shape[1]))
        return self._standardise(self.describe(found.frames).astype(np.float64))

    def _fit_heads(self) -> None:
        """The logistic head over every stored descriptor; the open set's centroids (one a
        scene, equal spreads) over the windows as heard, not their equalised copies."""
        self._fit_head()
        heard = ~self.train_derived_
        self.novelty_head_ = SceneCentroids.fit(
            self.train_descriptors_[heard],
            self.train_scenes_[heard],
            1,
            self.reject_quantile,
            self.reject_margin,
            self.random_state,
            NOVELTY_SHRINKAGE,
        )

    def _column_weights(self) -> np.ndarray:
        """Each descriptor column's scale in the head: 1 for the frame statistics,
        `encoding_weight` for the encodings."""
        weights = np.full(self.train_descriptors_.shape[1], float(self.encoding_weight))
        weights[: 3 * self.frame_mean_.shape[0]] = 1.0
        return weights

    def _fit_head(self) -> None:
        head = self._head(self.train_visits_)
        self.mode_scenes_, self.classes_ = head.mode_scenes, head.classes
        self.coef_, self.intercept_ = head.coef, head.intercept
        self.elsewhere_coef_, self.elsewhere_intercept_ = (
            head.elsewhere_coef,
            head.elsewhere_intercept,
        )
        self.place_coef_, self.place_intercept_ = self.coef_, self.intercept_
        if self.place_share and len(self.mode_scenes_) > len(self.classes_):
            places = self._head(self.train_scenes_)  # one visit a place
            self.place_coef_, self.place_intercept_ = places.coef, places.intercept

    def _head(self, visits: np.ndarray) -> VisitHead:
        """The logistic head over every stored descriptor, a class each of `visits`."""
        return fit_visit_head(
            self.train_descriptors_,
            self.train_scenes_,
            visits,
            self.background_descriptors_,
            self._column_weights(),
            C=self.C_,
            elsewhere_weight=self.elsewhere_weight,
        )

    def fold_in(self, X: np.ndarray, scenes: Sequence[str]) -> Self:
        """Add windows with confirmed labels: both heads are refitted on the stored training
        descriptors plus these (the codebooks stay), so a new scene becomes known."""
        if len(scenes) != len(X):
            raise ValueError(f"{len(X)} feature rows but {len(scenes)} scene labels")
        D = self.descriptors(X)
        # the windows folded in at once are one visit of their place, a new one
        visit = f"folded in {len(set(self.train_visits_.tolist()))}"
        self.train_descriptors_ = np.vstack([self.train_descriptors_, D])
        self.train_scenes_ = np.concatenate([self.train_scenes_, np.asarray(scenes, dtype=str)])
        self.train_visits_ = np.concatenate([self.train_visits_, np.full(len(D), visit)])
        self.train_derived_ = np.concatenate([self.train_derived_, np.zeros(len(D), bool)])
        self._fit_heads()
        return self

    # -- describing and deciding ------------------------------------------------------------

    def describe(self, X: np.ndarray) -> np.ndarray:
        """Frame statistics beside every codebook's triangle encoding, before standardising."""
        frames = np.asarray(X, dtype=np.float32)
        standard = (frames - self.frame_mean_) / self.frame_scale_
        parts = [frame_statistics(frames)]
        parts += [triangle_encoding(standard, codebook) for codebook in self.codebooks_]
        return np.concatenate(parts, axis=1)

    def _standardise(self, D: np.ndarray) -> np.ndarray:
        return (D - self.descriptor_mean_) / self.descriptor_scale_

    def descriptors(self, X: np.ndarray) -> np.ndarray:
        self._check_fitted()
        return self._standardise(self.describe(X))

    def _space(self, X: np.ndarray) -> np.ndarray:
        return self.descriptors(X)

    @property
    def scenes_(self) -> list[str]:
        self._check_fitted()
        return self.classes_

    def _check_fitted(self) -> None:
        if not hasattr(self, "coef_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit first")

    def _proba(self, D: np.ndarray) -> np.ndarray:
        """Each place's likeliest visit's share among the taught places; with a `place_share`,
        mixed with that share of a head with one class a place (`place_coef_`: the same head
        where every place is one visit)."""
        mode_proba = softmax_proba((D @ self.coef_.T + self.intercept_) / self.temperature)
        places = place_proba(mode_proba, self.mode_scenes_, self.classes_)
        places = places / places.sum(axis=1, keepdims=True)
        if not self.place_share:
            return places
        logits = D @ self.place_coef_.T + self.place_intercept_
        kinds = softmax_proba(logits / self.temperature)
        return (1.0 - self.place_share) * places + self.place_share * kinds

    @property
    def knows_elsewhere(self) -> bool:
        return len(self.elsewhere_coef_) > 0

    def _unlike_taught(self, D: np.ndarray, names: np.ndarray) -> np.ndarray:
        """(n,) bool: rows whose nearest window of their named place, as taught (not the
        equalised copies), is at a cosine below that place's acceptance (`_acceptance`) in the
        standardised space: a place is only this window's if the wearer was taught something
        like it there. No acceptance: no such check (`kmeans-encoder`, whose centroids are its
        distance check)."""
        unlike = np.zeros(len(D), dtype=bool)
        if self.accept_cosine is None:
            return unlike
        rows = unit_rows(D)
        for place in set(np.asarray(names).tolist()) & set(self.classes_):
            taught = self._taught_rows(place)
            if not len(taught):  # only equalised copies of it: nothing heard to compare with
                continue
            here = np.asarray(names) == place
            unlike[here] = np.max(rows[here] @ taught.T, axis=1) < self._acceptance(place)
        return unlike

    def _taught_rows(self, place: str) -> np.ndarray:
        """The unit-length descriptors of the windows `place` was taught on, as heard."""
        heard = ~self.train_derived_
        return unit_rows(self.train_descriptors_[heard & (self.train_scenes_ == place)])

    def _acceptance(self, place: str) -> float:
        """The cosine a window needs to one of `place`'s taught windows to be named it:
        `accept_cosine`, or, calibrated (`calibrated_accept`), the nearest any window of the
        background (somewhere else, by definition) comes to them: a window is this place's only
        if it is more like what the wearer taught here than anything elsewhere is."""
        if not self.calibrated_accept or not len(self.background_descriptors_):
            return float(self.accept_cosine or 0.0)
        near = unit_rows(self.background_descriptors_) @ self._taught_rows(place).T
        return float(np.max(near)) if near.size else float(self.accept_cosine or 0.0)

    def _open_proba(self, D: np.ndarray) -> np.ndarray:
        """(n, scenes): the probability of each taught place and not somewhere else; the rest
        of each row is `<elsewhere>`'s (none without a background)."""
        coef = np.vstack([self.coef_, self.elsewhere_coef_])
        intercept = np.concatenate([self.intercept_, self.elsewhere_intercept_])
        proba = softmax_proba((D @ coef.T + intercept) / self.temperature)
        mode_proba = proba[:, : len(self.mode_scenes_)]
        return place_proba(mode_proba, self.mode_scenes_, self.classes_, together=True)

    # -- model files ------------------------------------------------------------------------

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        self._check_fitted()
        novelty, novelty_arrays = self.novelty_head_.state()
        header = {
            "params": self.params(),
            "C_": self.C_,
            "classes": self.classes_,
            "scenes": self.scenes_,
            "novelty": novelty,
        }
        arrays = {
            **self._featurizer_arrays(),
            "descriptor_mean": self.descriptor_mean_,
            "descriptor_scale": self.descriptor_scale_,
            "coef": self.coef_,
            "intercept": self.intercept_,
            "train_descriptors": self.train_descriptors_.astype(np.float32),
            "train_scenes": self.train_scenes_.astype(str),
            "train_visits": self.train_visits_.astype(str),
            "mode_scenes": self.mode_scenes_.astype(str),
            "train_derived": self.train_derived_,
            "background_descriptors": self.background_descriptors_.astype(np.float32),
            "elsewhere_coef": self.elsewhere_coef_,
            "elsewhere_intercept": self.elsewhere_intercept_,
            "place_coef": self.place_coef_,
            "place_intercept": self.place_intercept_,
            **{f"novelty_{k}": v for k, v in novelty_arrays.items()},
        }
        return header, arrays

    def _featurizer_arrays(self) -> dict[str, np.ndarray]:
        """What describing a window learned in `fit` (the frames' scale, the codebooks)."""
        return {
            "frame_mean": self.frame_mean_,
            "frame_scale": self.frame_scale_,
            "codebooks": self.codebooks_,
        }

    def _read_featurizer(self, arrays: dict[str, np.ndarray]) -> None:
        self.frame_mean_ = np.asarray(arrays["frame_mean"], dtype=np.float32)
        self.frame_scale_ = np.asarray(arrays["frame_scale"], dtype=np.float32)
        self.codebooks_ = np.asarray(arrays["codebooks"], dtype=np.float32)

    @classmethod
    def from_state(cls, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self:
        model = cls(**{**cls.legacy_params, **header["params"]})
        model.classes_ = [str(c) for c in header["classes"]]
        chosen = header.get("C_", model.C)  # saved before C_: C itself
        if not isinstance(chosen, int | float) or not 0 < chosen < float("inf"):
            raise ValueError(f"its head's C is {chosen!r}")
        model.C_ = float(chosen)
        model._read_featurizer(arrays)
        model.descriptor_mean_ = np.asarray(arrays["descriptor_mean"], dtype=np.float64)
        model.descriptor_scale_ = np.asarray(arrays["descriptor_scale"], dtype=np.float64)
        model.coef_ = np.asarray(arrays["coef"], dtype=np.float64)
        model.intercept_ = np.asarray(arrays["intercept"], dtype=np.float64)
        model.train_descriptors_ = np.asarray(arrays["train_descriptors"], dtype=np.float64)
        model.train_scenes_ = np.asarray(arrays["train_scenes"]).astype(str)
        # a model file saved before visits had one a place: its head's rows are its places
        visits = arrays.get("train_visits", model.train_scenes_)
        model.train_visits_ = np.asarray(visits).astype(str)
        model.mode_scenes_ = np.asarray(arrays.get("mode_scenes", model.classes_)).astype(str)
        fits = (
            sorted(set(model.mode_scenes_.tolist())) == sorted(model.classes_)
            and len(model.mode_scenes_) == len(model.coef_)
            and len(model.train_visits_) == len(model.train_scenes_)
        )
        if not fits:
            raise ValueError("its head's rows do not match its places")
        model.train_derived_ = np.asarray(arrays["train_derived"], dtype=bool)
        width = model.train_descriptors_.shape[1]
        # a model file saved before the background had none: nothing is "somewhere else"
        model.background_descriptors_ = np.asarray(
            arrays.get("background_descriptors", np.empty((0, width))), dtype=np.float64
        )
        model.elsewhere_coef_ = np.asarray(
            arrays.get("elsewhere_coef", np.empty((0, width))), dtype=np.float64
        )
        model.elsewhere_intercept_ = np.asarray(
            arrays.get("elsewhere_intercept", np.empty(0)), dtype=np.float64
        )
        # a model file saved before the head with one class a place mixes none of it in
        # (`legacy_params`): its rows are then never read
        model.place_coef_ = np.asarray(arrays.get("place_coef", model.coef_), dtype=np.float64)
        model.place_intercept_ = np.asarray(
            arrays.get("place_intercept", model.intercept_), dtype=np.float64
        )
        if model.place_share and len(model.place_coef_) != len(model.classes_):
            raise ValueError("its place head's rows do not match its places")
        prefixed = {k[len("novelty_") :]: v for k, v in arrays.items() if k.startswith("novelty_")}
        model.novelty_head_ = SceneCentroids.from_state(header["novelty"], prefixed)
        return model
