"""What every recogniser is, and the pieces they share: labelling clusters, spreads, probabilities.

A recogniser is a scikit-learn-style estimator for one sense: stateless `featurize(items)` →
(n, ...); `fit(X, scenes)` → `self`, learned attributes ending in `_`, `scenes_` in
`predict_proba`'s column order; `predict(X)` (`UNKNOWN` where none), `confidence(X)` in
`confidence_unit`, `predict_proba(X)` (rows sum to one); `open_proba(X)` when it knows somewhere
else (rows sum to at most one); `get_state()` / `from_state(header, arrays)`, saved without
pickle (`servant_core.modelfile`). What one can do beyond that it declares (`Capabilities`)."""

from __future__ import annotations

import inspect
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Protocol, Self, cast

import numpy as np

from servant_core.errors import ServantError
from servant_core.senses import UNKNOWN as UNKNOWN  # where every recogniser names it

PERCENT = "%"


class Recogniser(Protocol):
    method: ClassVar[str]
    sense: ClassVar[str]
    confidence_unit: ClassVar[str]
    # what it can do beyond the protocol, declared: `Capabilities`
    folds_in: ClassVar[bool]
    learns_visits: ClassVar[bool]

    @property
    def scenes_(self) -> list[str]:
        """Read-only here: a method may keep it as an attribute or derive it (`CentroidRecogniser`
        reads it from its centroids, which a fold-in can extend)."""
        ...

    # Stateless, depends only on the parameters. Audio: windows, a float32 array (n, samples) at
    # `self.rate`; image: a list of BGR uint8 pictures. Returns (n, ...).
    def featurize(self, items: Any) -> np.ndarray: ...
    def fit(self, X: np.ndarray, scenes: Sequence[str] | np.ndarray) -> Self: ...
    def predict(self, X: np.ndarray) -> np.ndarray: ...
    # A number whose unit `confidence_unit` names: `PERCENT` (a probability in percent) or, in
    # paper mode, the paper's formula ("eq. 1", "eq. 2"), which is no percentage.
    def confidence(self, X: np.ndarray) -> np.ndarray: ...
    # (n, len(scenes_)) rows summing to one: the shares among the taught places.
    def predict_proba(self, X: np.ndarray) -> np.ndarray: ...
    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]: ...

    @classmethod
    def from_state(cls, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> Self: ...

    # What it can be asked beyond scikit-learn's classifier, declared (`TaughtPlacesOnly` gives
    # the answers of a recogniser that knows only the taught places): whether its open
    # probabilities leave room for somewhere else, those probabilities, and all three answers
    # the live engine asks of a row at once.
    @property
    def knows_elsewhere(self) -> bool: ...
    def open_proba(self, X: np.ndarray) -> np.ndarray: ...
    def answers(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
    def matched_palette(self, X: np.ndarray) -> np.ndarray | None: ...
    def fit_warnings(self) -> list[str]: ...


class Capabilities:
    """What a recogniser can do beyond the protocol, declared by its class as scikit-learn's
    estimator tags are, so that the engine reads them and never probes; each default says it
    cannot. `tests/test_capabilities.py` checks every registered recogniser's declarations."""

    # `fold_in(X, scenes)` adds labelled rows without a refit (else a label waits for a retrain)
    folds_in: ClassVar[bool] = False
    # `fit(X, scenes, visits=)` learns a place's visits apart (`fit_visits`)
    learns_visits: ClassVar[bool] = False
    # the universal background it keeps its places against, which the recordings in its
    # `background_exclude` parameter are kept out of (`background.kept_out`); None: none
    background_path: ClassVar[Path | None] = None

    def matched_palette(self, X: np.ndarray) -> np.ndarray | None:
        """The training palette each row matched (k RGB colours a row); None: it keeps none."""
        return None

    def fit_warnings(self) -> list[str]:
        """What the fit found wrong with what it was taught (none by default)."""
        return []


class TaughtPlacesOnly(Capabilities):
    """The answers of a recogniser that knows only the places it was taught (a mixin for the
    paper's recognisers, the centroids' and the benches' peers): no room for somewhere else,
    its open probabilities its shares, its names `predict`'s."""

    knows_elsewhere: ClassVar[bool] = False

    def open_proba(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(self.predict_proba(X), dtype=float)  # type: ignore[attr-defined]

    def confidence(self, X: np.ndarray) -> np.ndarray:
        """The likeliest place's share in percent (a method with its own unit overrides it)."""
        return 100.0 * np.max(self.open_proba(X), axis=1)

    def answers(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(`predict`, `confidence`, `predict_proba`) of rows `X`."""
        names = np.asarray(self.predict(X)).astype(str)  # type: ignore[attr-defined]
        confidence = np.asarray(self.confidence(X), dtype=np.float64)  # type: ignore[attr-defined]
        return names, confidence, self.open_proba(X)


class AcousticRecogniser(Recogniser, Protocol):
    """A recogniser of windows (the sound's, a sample sense's) also says at what rate and window
    length it featurizes them."""

    rate: int
    window_seconds: float


def windowed(recogniser: Recogniser) -> AcousticRecogniser:
    """`recogniser`, one of windows of samples (the sound's, a sample sense's), as the type that
    declares their `rate` and `window_seconds`."""
    return cast(AcousticRecogniser, recogniser)


@dataclass
class ClusterLabels:
    """Which scene each cluster stands for, by majority of its training members.

    `cluster_scene[c]` is None for a cluster with no members or with a tie at the top;
    `unowned_scenes` are scenes that no cluster stands for. Both are reported, never hidden.
    """

    cluster_scene: list[str | None]
    tied_clusters: list[int] = field(default_factory=list)
    empty_clusters: list[int] = field(default_factory=list)
    unowned_scenes: list[str] = field(default_factory=list)

    def warnings(self) -> list[str]:
        lines = [f"cluster {c} has no majority scene (tie)" for c in self.tied_clusters]
        lines += [f"cluster {c} has no training member" for c in self.empty_clusters]
        lines += [
            f"scene {s!r} owns no cluster: it can never be predicted" for s in self.unowned_scenes
        ]
        return lines


def label_clusters(
    clusters: np.ndarray, scenes: Sequence[str] | np.ndarray, n_clusters: int
) -> ClusterLabels:
    """Give each cluster the scene most of its members carry (pure; ties give None)."""
    cluster_scene: list[str | None] = []
    tied: list[int] = []
    empty: list[int] = []
    scenes_arr = np.asarray(scenes)
    for c in range(n_clusters):
        counts = Counter(scenes_arr[clusters == c].tolist()).most_common()
        if not counts:
            cluster_scene.append(None)
            empty.append(c)
        elif len(counts) > 1 and counts[0][1] == counts[1][1]:
            cluster_scene.append(None)
            tied.append(c)
        else:
            cluster_scene.append(counts[0][0])
    owned = {s for s in cluster_scene if s is not None}
    unowned = sorted(set(scenes_arr.tolist()) - owned)
    return ClusterLabels(cluster_scene, tied, empty, unowned)


def check_training_scenes(scenes: Sequence[str] | np.ndarray, n_rows: int) -> list[str]:
    """The sorted distinct scenes; K-Means with one cluster per scene needs at least two."""
    if len(scenes) != n_rows:
        raise ValueError(f"{n_rows} feature rows but {len(scenes)} scene labels")
    distinct = sorted(set(scenes))
    if len(distinct) < 2:
        found = distinct[0] if distinct else "none"
        raise ServantError(
            f"training needs at least two scenes, found one ({found}); add a second scene folder"
        )
    return distinct


def fit_visits(model: Any, X: np.ndarray, scenes: Any, visits: np.ndarray | None) -> Any:
    """`model.fit(X, scenes)`, telling a method that learns a place's visits apart (one that
    declares `learns_visits`) which visit each row comes from (`library.visits_of`)."""
    if visits is not None and model.learns_visits:
        return model.fit(X, scenes, visits=visits)
    return model.fit(X, scenes)


def cluster_spreads(X: np.ndarray, clusters: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Root-mean-square distance of each cluster's members to their centre (its own spread).

    An empty or single-member cluster takes the median spread of the others, so it is neither
    infinitely sharp nor infinitely vague. Distances are taken row by row against the centres
    (an (n, K) matrix), never as a copy of the members: X can be hundreds of megabytes.
    """
    from sklearn.metrics.pairwise import euclidean_distances

    own = euclidean_distances(X, centres)[np.arange(len(X)), clusters]
    spreads = np.full(len(centres), np.nan)
    for c in range(len(centres)):
        members = own[clusters == c]
        if len(members) > 1:
            spreads[c] = np.sqrt(np.mean(members.astype(float) ** 2))
    fallback = np.nanmedian(spreads) if np.any(np.isfinite(spreads)) else 1.0
    spreads[~np.isfinite(spreads) | (spreads <= 0)] = fallback if fallback > 0 else 1.0
    return spreads


def scene_probabilities(
    distances: np.ndarray,
    spreads: np.ndarray,
    cluster_scene: Sequence[str | None],
    scenes: Sequence[str],
) -> np.ndarray:
    """Per-scene probabilities from distances to centres, each scaled by its cluster's spread.

    A Gaussian likelihood per cluster, exp(-d²/2σ²)/σ^…, summed over the clusters of a scene and
    normalised (computed in log space so that far points do not underflow to 0/0).
    Clusters without a scene take no part.
    """
    scaled = distances / spreads[None, :]
    log_like = -0.5 * scaled**2 - np.log(spreads)[None, :]
    out = np.full((len(distances), len(scenes)), -np.inf)
    for j, scene in enumerate(scenes):
        cols = [c for c, s in enumerate(cluster_scene) if s == scene]
        if cols:
            out[:, j] = np.logaddexp.reduce(log_like[:, cols], axis=1)
    top = np.max(out, axis=1, keepdims=True)
    top[~np.isfinite(top)] = 0.0
    probs = np.exp(out - top)
    total = probs.sum(axis=1, keepdims=True)
    uniform = np.full_like(probs, 1.0 / len(scenes))
    return np.where(total > 0, probs / np.where(total > 0, total, 1.0), uniform)


def open_probabilities(recogniser: Recogniser, X: np.ndarray) -> np.ndarray:
    """(n, scenes): each taught place's probability and not somewhere else, where the recogniser
    knows somewhere else (`open_proba`); otherwise its shares among the taught places."""
    return np.asarray(recogniser.open_proba(X), dtype=float)


def open_predict(recogniser: Recogniser, X: np.ndarray) -> np.ndarray:
    """`predict`, and `UNKNOWN` too where the recogniser knows somewhere else and gives it half
    the probability or more (the wearer is more likely in a place not taught than in any taught)
    or, where it has one, its acceptance check says the row is unlike what its place was taught
    on (`birdnet`'s nearest taught window). What the live engine, `servant predict` and the
    arm go by; `predict` alone says which taught place a row is likeliest (what the evaluation
    protocols score)."""
    return np.asarray(recogniser.answers(X)[0]).astype(str)


def elsewhere_unnamed(names: np.ndarray, open_p: np.ndarray) -> np.ndarray:
    """`names` with `UNKNOWN` where somewhere else has half the probability or more (what is
    left of each row of taught places' open probabilities `open_p`)."""
    names = np.asarray(names, dtype=object).copy()
    names[np.asarray(open_p).sum(axis=1) <= 0.5] = UNKNOWN
    return names


def answers(recogniser: Recogniser, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(`open_predict`, `confidence`, `open_probabilities`) of rows `X`, in one pass."""
    return recogniser.answers(X)


def knows_elsewhere(recogniser: Recogniser | None) -> bool:
    """Whether the recogniser's `open_probabilities` leave room for somewhere else (None: no
    recogniser, no room)."""
    return recogniser is not None and bool(recogniser.knows_elsewhere)


def init_params(estimator: Any) -> dict[str, Any]:
    """The estimator's parameters: each keyword of its `__init__`, as stored on it (sequences as
    lists), the way scikit-learn's `get_params` reads them; what a model file keeps."""
    names = [
        name
        for name, parameter in inspect.signature(type(estimator).__init__).parameters.items()
        if parameter.kind is inspect.Parameter.KEYWORD_ONLY
    ]
    values = {name: getattr(estimator, name) for name in names}
    return {name: list(v) if isinstance(v, tuple) else v for name, v in values.items()}
