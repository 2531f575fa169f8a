"""The learned fusion's net (the paper's Fig. 7): every sense's opinion in, a scene out.

Per sense of `senses_`, `FusionNet` reads its probabilities over `scenes_` (zeros when absent),
an *absent* flag, the share of its opinions that said `<unknown>` and how many were pooled (over
`pool`). It learns from the recognisers' held-out opinions (`fusion.learning`), each row also
with random senses dropped; its threshold is the lowest top probability right `target_precision`
of the time on held-out folds. `get_state`/`from_state` keep the weights as arrays beside a JSON
header, and a loaded net decides exactly as the trained one (a numpy pass over them)."""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Self

import numpy as np
from sklearn.exceptions import ConvergenceWarning, NotFittedError
from sklearn.neural_network import MLPClassifier
from threadpoolctl import threadpool_limits

from servant_core.errors import ServantError
from servant_core.perceptron import ACTIVATIONS, forward
from servant_core.recognisers.base import UNKNOWN, init_params

# Features per sense beside its probabilities: the absent flag, the unknown share and the share
# of `pool` opinions pooled. Nets saved before the last was added read two (`LEGACY_FLAGS`).
FLAGS = 3
LEGACY_FLAGS = 2
# Copies with senses dropped of each held-out row the threshold is chosen on (10 halve the
# spread of the threshold between random states that 3 gave: docs/research.md).
HELD_OUT_COPIES = 10
MAX_SENSES = 16
MAX_SCENES = 1000
# A sense whose removal lowers the decided scene's probability by this much was leaned on.
LEAN_MARGIN = 0.02


# A sense's pooled opinion as the net reads it: its probability per scene, the share of its
# opinions that named no scene, and how many opinions were pooled (missing: a full pool).
Pooled = tuple[Mapping[str, float], float] | tuple[Mapping[str, float], float, int]


@dataclass
class SenseOpinions:
    """What one sense's recogniser said about held-out items: the training material of the net.

    `proba` (n, len(scenes)) are its probabilities in the column order of `scenes` (its
    recogniser's `scenes_`); `predicted` its scene names (`<unknown>` where it named none);
    `truth` the scene each item really is; `fold` the cross-validation fold of each item
    (0..k-1), the same folds its opinions were held out by.
    """

    proba: np.ndarray
    scenes: list[str]
    predicted: np.ndarray
    truth: np.ndarray
    fold: np.ndarray


def teaching_shortfall(
    opinions: Mapping[str, SenseOpinions], min_per_scene: int, min_folds: int = 2
) -> str | None:
    """Why the net cannot be taught from `opinions` (None: it can): fewer than two scenes, a
    scene with fewer than `min_per_scene` opinions from every sense, or fewer than `min_folds`
    folds. The caller then keeps a rule policy."""
    counts: dict[str, int] = {}
    folds: set[int] = set()
    for sense in opinions.values():
        scenes, n = np.unique(sense.truth, return_counts=True)
        for scene, count in zip(scenes.tolist(), n.tolist(), strict=True):
            counts[scene] = max(counts.get(scene, 0), count)
        folds |= set(np.unique(sense.fold).tolist())
    if len(counts) < 2:
        return f"the learned fusion needs two taught scenes or more, not {len(counts)}"
    short = sorted(s for s, n in counts.items() if n < min_per_scene)
    if short:
        return (
            f"the learned fusion needs {min_per_scene} windows or pictures per scene; too few "
            f"of {', '.join(short)}"
        )
    if len(folds) < min_folds:
        return f"the learned fusion needs items in {min_folds} folds or more, not {len(folds)}"
    return None


def training_rows(
    opinions: Mapping[str, SenseOpinions],
    senses: Sequence[str],
    scenes: Sequence[str],
    folds: Sequence[int],
    pool: int,
    copies: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Training rows made from the opinions of `folds` only: for each scene, as many rows as its
    most-seen sense has opinions there (`_pooled_row`), each once whole and `copies` more times
    with random senses dropped (`_dropped`)."""
    width = len(scenes) + FLAGS
    rows: list[np.ndarray] = []
    labels: list[str] = []
    in_folds = {name: np.isin(o.fold, list(folds)) for name, o in opinions.items()}
    mapped = {name: _columns(o, scenes) for name, o in opinions.items()}
    for scene in scenes:
        members = {
            name: np.flatnonzero(in_folds[name] & (o.truth == scene))
            for name, o in opinions.items()
        }
        n_rows = max((len(m) for m in members.values()), default=0)
        for _ in range(n_rows):
            row, present = _pooled_row(opinions, mapped, members, senses, len(scenes), pool, rng)
            if not present:
                continue
            rows.append(row)
            rows.extend(_dropped(row, present, len(scenes), rng) for _ in range(copies))
            labels.extend([scene] * (copies + 1))
    return np.array(rows).reshape(-1, len(senses) * width), np.array(labels)


def _pooled_row(
    opinions: Mapping[str, SenseOpinions],
    mapped: Mapping[str, np.ndarray],
    members: Mapping[str, np.ndarray],
    senses: Sequence[str],
    n_scenes: int,
    pool: int,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[int]]:
    """One row of a scene, and which senses it holds: each sense's part is the mean of 1..`pool`
    of its opinions `members` (as the policy pools a sense's recent opinions), their unknown
    share and how many were pooled over `pool`; a sense without opinions is absent."""
    width = n_scenes + FLAGS
    row = np.zeros(len(senses) * width)
    present = []
    for i, sense in enumerate(senses):
        block = row[i * width : (i + 1) * width]
        chosen = members.get(sense, np.empty(0, int))
        if len(chosen) == 0:
            block[n_scenes] = 1.0
            continue
        picked = rng.choice(chosen, size=int(rng.integers(1, pool + 1)))
        block[:n_scenes] = mapped[sense][picked].mean(axis=0)
        block[n_scenes + 1] = np.mean(opinions[sense].predicted[picked] == UNKNOWN)
        block[n_scenes + 2] = len(picked) / pool
        present.append(i)
    return row, present


def _dropped(
    row: np.ndarray, present: Sequence[int], n_scenes: int, rng: np.random.Generator
) -> np.ndarray:
    """A copy of `row` with random senses of `present` dropped (at least one kept): each dropped
    sense absent, or present but naming no scene (flat probabilities, all its opinions
    `<unknown>`), so that the net learns what a sense naming nothing means."""
    width = n_scenes + FLAGS
    kept = [i for i in present if rng.random() < 0.5] or [int(rng.choice(present))]
    dropped = row.copy()
    for i in set(present) - set(kept):
        block = dropped[i * width : (i + 1) * width]
        if rng.random() < 0.5:  # gone
            block[:] = 0.0
            block[n_scenes] = 1.0
        else:  # there, but at a place it does not know: it names no scene
            block[:n_scenes] = 1.0 / n_scenes
            block[n_scenes + 1] = 1.0
    return dropped


def _columns(opinions: SenseOpinions, scenes: Sequence[str]) -> np.ndarray:
    """The sense's probabilities in `scenes` order (0 for a scene its recogniser does not know)."""
    out = np.zeros((len(opinions.proba), len(scenes)))
    index = {s: j for j, s in enumerate(opinions.scenes)}
    for k, scene in enumerate(scenes):
        if scene in index:
            out[:, k] = opinions.proba[:, index[scene]]
    return out


def precision_threshold(top: np.ndarray, right: np.ndarray, target: float) -> float:
    """The lowest threshold on the top probability at which the rows decided (top ≥ threshold)
    are right at least `target` of the time; 1.0 (never decide) if none is."""
    order = np.argsort(-top, kind="stable")
    hits = np.cumsum(right[order])
    precision = hits / np.arange(1, len(order) + 1)
    ok = np.flatnonzero(precision >= target)
    if len(ok) == 0:
        return 1.0
    # ties: the threshold is a value, so every row sharing it is decided too
    threshold = float(top[order][ok[-1]])
    decided = top >= threshold
    if np.mean(right[decided]) < target:
        return float(np.nextafter(threshold, 2.0))
    return threshold


class FusionNet:
    """Per-sense probabilities and flags → scene, a small MLP (scikit-learn's `MLPClassifier`).

    `fit(opinions)` takes a `SenseOpinions` per sense; `threshold_` is the lowest top
    probability at which held-out rows were right at least `target_precision` of the time.
    """

    def __init__(
        self,
        *,
        hidden_layer_sizes: tuple[int, ...] = (24,),
        activation: str = "tanh",
        alpha: float = 1e-3,
        max_iter: int = 400,
        pool: int = 10,
        pictures_needed: int = 3,
        dropout_copies: int = 3,
        target_precision: float = 0.99,
        min_per_scene: int = 5,
        random_state: int = 0,
    ) -> None:
        self.hidden_layer_sizes = hidden_layer_sizes
        self.activation = activation
        self.alpha = alpha
        self.max_iter = max_iter
        self.pool = pool
        self.pictures_needed = pictures_needed
        self.dropout_copies = dropout_copies
        self.target_precision = target_precision
        self.min_per_scene = min_per_scene
        self.random_state = random_state

    # -- learning ---------------------------------------------------------------------------

    def shortfall(self, opinions: Mapping[str, SenseOpinions]) -> str | None:
        """Why these opinions are too little to learn from (None: enough); see
        `teaching_shortfall`."""
        return teaching_shortfall(opinions, self.min_per_scene)

    def fit(self, opinions: Mapping[str, SenseOpinions]) -> Self:
        """Learn from each sense's held-out opinions; the threshold comes from training on all
        folds but one and scoring that one, in turn. Too little to learn from: ServantError."""
        if self.activation not in ACTIVATIONS:
            raise ServantError(
                f"activation {self.activation!r} is unknown; use one of {', '.join(ACTIVATIONS)}"
            )
        reason = self.shortfall(opinions)
        if reason is not None:
            raise ServantError(reason)
        senses = sorted(opinions)
        scenes = sorted({s for o in opinions.values() for s in o.truth.tolist()})
        folds = sorted({f for o in opinions.values() for f in o.fold.tolist()})
        rng = np.random.default_rng(self.random_state)
        top: list[np.ndarray] = []
        right: list[np.ndarray] = []
        for held in folds:
            others = [f for f in folds if f != held]
            X, y = training_rows(
                opinions, senses, scenes, others, self.pool, self.dropout_copies, rng
            )
            X_held, y_held = training_rows(
                opinions, senses, scenes, [held], self.pool, HELD_OUT_COPIES, rng
            )
            if len(X_held) == 0 or len(set(y.tolist())) < 2:
                continue
            net = self._train(X, y)
            proba = net.predict_proba(X_held)
            deciding = self._decidable(X_held, senses, len(scenes))
            top.append(proba.max(axis=1)[deciding])
            right.append((net.classes_[proba.argmax(axis=1)] == y_held)[deciding])
        X, y = training_rows(opinions, senses, scenes, folds, self.pool, self.dropout_copies, rng)
        net = self._train(X, y)
        self.senses_ = senses
        self.scenes_ = [str(s) for s in net.classes_]
        self.coefs_ = [w.copy() for w in net.coefs_]
        self.intercepts_ = [b.copy() for b in net.intercepts_]
        self.flags_ = FLAGS
        self.threshold_ = (
            precision_threshold(np.concatenate(top), np.concatenate(right), self.target_precision)
            if top
            else 1.0
        )
        self.n_rows_ = len(y)
        return self

    def needs(self, sense: str) -> int:
        """How many opinions `sense` must have given for the net to decide on it alone: a picture
        is a glimpse, so the camera needs `pictures_needed` (the paper's confirmation); a 5 s
        window of any other sense is a whole judgement."""
        return self.pictures_needed if sense == "image" else 1

    def said_enough(self, opinions: Mapping[str, Pooled]) -> bool:
        """Whether some sense has named a scene (not `<unknown>`) as often as it `needs`
        (without a count: one opinion)."""
        return any(
            round((opinion[2] if len(opinion) > 2 else 1) * (1.0 - opinion[1]))  # type: ignore[misc]
            >= self.needs(sense)
            for sense, opinion in opinions.items()
        )

    def _decidable(self, X: np.ndarray, senses: Sequence[str], n_scenes: int) -> np.ndarray:
        """Which training rows `said_enough` would let the net decide on (read from the rows'
        absent flags and pooled shares)."""
        width = n_scenes + FLAGS
        ok = np.zeros(len(X), dtype=bool)
        for i, sense in enumerate(senses):
            present = X[:, i * width + n_scenes] == 0.0
            known = 1.0 - X[:, i * width + n_scenes + 1]
            said = np.rint(X[:, i * width + n_scenes + 2] * self.pool * known)
            ok |= present & (said >= self.needs(sense))
        return ok

    def _train(self, X: np.ndarray, y: np.ndarray) -> MLPClassifier:
        net = MLPClassifier(
            hidden_layer_sizes=self.hidden_layer_sizes,
            activation=self.activation,
            alpha=self.alpha,
            max_iter=self.max_iter,
            random_state=self.random_state,
        )
        # One BLAS thread: the matrices are tiny (see servant_core/actions/learner.py).
        with warnings.catch_warnings(), threadpool_limits(1, user_api="blas"):
            warnings.simplefilter("ignore", ConvergenceWarning)
            return net.fit(X, y)

    # -- deciding ---------------------------------------------------------------------------

    def _check_fitted(self) -> None:
        if not hasattr(self, "coefs_"):
            raise NotFittedError("this FusionNet has not been fitted; call fit(opinions) first")

    def features(self, opinions: Mapping[str, Pooled]) -> np.ndarray:
        """One input row from {sense: (scores per scene, unknown share[, opinions pooled])}; a
        sense of `senses_` not given is absent; a sense the net was not taught is ignored."""
        self._check_fitted()
        width = len(self.scenes_) + self.flags_
        row = np.zeros(len(self.senses_) * width)
        for i, sense in enumerate(self.senses_):
            block = row[i * width : (i + 1) * width]
            if sense not in opinions:
                block[len(self.scenes_)] = 1.0
                continue
            scores, unknown = opinions[sense][0], opinions[sense][1]
            block[: len(self.scenes_)] = [float(scores.get(s, 0.0)) for s in self.scenes_]
            block[len(self.scenes_) + 1] = float(unknown)
            if self.flags_ > LEGACY_FLAGS:
                pooled = opinions[sense][2] if len(opinions[sense]) > 2 else self.pool  # type: ignore[misc]
                block[len(self.scenes_) + 2] = min(int(pooled), self.pool) / self.pool
        return row

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        """(n, len(scenes_)) probabilities, through a numpy pass over the stored weights."""
        self._check_fitted()
        out = forward(np.atleast_2d(X), self.coefs_, self.intercepts_, self.activation)
        if out.shape[1] == 1:  # two scenes: scikit-learn keeps one logistic output
            p = 1.0 / (1.0 + np.exp(-out[:, 0]))
            return np.column_stack([1.0 - p, p])
        out = out - out.max(axis=1, keepdims=True)
        e = np.exp(out)
        return e / e.sum(axis=1, keepdims=True)

    def predict(self, X: np.ndarray) -> np.ndarray:
        return np.array(self.scenes_)[self.predict_proba(X).argmax(axis=1)]

    # -- files ------------------------------------------------------------------------------

    def get_state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """A JSON-able header and the weight arrays (see `servant_core.modelfile`)."""
        self._check_fitted()
        header = {
            "params": init_params(self),
            "senses": list(self.senses_),
            "scenes": list(self.scenes_),
            "threshold": self.threshold_,
            "n_rows": self.n_rows_,
            "flags": self.flags_,
        }
        arrays = {f"coef_{i}": w for i, w in enumerate(self.coefs_)}
        arrays |= {f"intercept_{i}": b for i, b in enumerate(self.intercepts_)}
        return header, arrays

    @classmethod
    def from_state(cls, header: Mapping[str, Any], arrays: Mapping[str, np.ndarray]) -> Self:
        """Rebuild a net from `get_state`'s output; anything inconsistent is a ValueError (the
        model file reports it as damage)."""
        params = dict(header["params"])
        params["hidden_layer_sizes"] = tuple(int(h) for h in params["hidden_layer_sizes"])
        net = cls(**params)
        if net.activation not in ACTIVATIONS:
            raise ValueError(f"activation {str(net.activation)[:20]!r}")
        if not all(1 <= h <= 4096 for h in net.hidden_layer_sizes) or not net.hidden_layer_sizes:
            raise ValueError("hidden layer sizes out of range")
        senses, scenes = header["senses"], header["scenes"]
        for name, names, most in (("senses", senses, MAX_SENSES), ("scenes", scenes, MAX_SCENES)):
            if (
                not isinstance(names, list)
                or not (1 if name == "senses" else 2) <= len(names) <= most
                or not all(isinstance(s, str) and s and s != UNKNOWN for s in names)
                or len(set(names)) != len(names)
            ):
                raise ValueError(f"its {name} are not a list of distinct names")
        threshold = header["threshold"]
        if type(threshold) not in (int, float) or not 0.0 <= threshold <= 1.0:
            raise ValueError(f"threshold {str(threshold)[:20]!r}")
        n_rows = header["n_rows"]
        if type(n_rows) is not int or n_rows < 0:
            raise ValueError(f"n_rows {str(n_rows)[:20]!r}")
        flags = header.get("flags", LEGACY_FLAGS)  # saved before the count was read: two
        if type(flags) is not int or flags not in (LEGACY_FLAGS, FLAGS):
            raise ValueError(f"flags {str(flags)[:20]!r}")
        if type(net.pool) is not int or not 1 <= net.pool <= 1000:
            raise ValueError(f"pool {str(net.pool)[:20]!r}")
        layers = len(net.hidden_layer_sizes) + 1
        expected = {f"coef_{i}" for i in range(layers)} | {f"intercept_{i}" for i in range(layers)}
        if set(arrays) != expected:
            raise ValueError(f"arrays {sorted(arrays)[:8]} instead of {sorted(expected)}")
        widths = [
            len(senses) * (len(scenes) + flags),
            *net.hidden_layer_sizes,
            len(scenes) if len(scenes) > 2 else 1,
        ]
        coefs, intercepts = [], []
        for i in range(layers):
            w, b = np.asarray(arrays[f"coef_{i}"]), np.asarray(arrays[f"intercept_{i}"])
            if w.shape != (widths[i], widths[i + 1]) or b.shape != (widths[i + 1],):
                raise ValueError(f"layer {i} of shape {w.shape}, {b.shape}")
            if w.dtype.kind != "f" or b.dtype.kind != "f":
                raise ValueError(f"layer {i} does not hold numbers")
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise ValueError(f"layer {i} holds NaN or infinity")
            coefs.append(w.astype(float))
            intercepts.append(b.astype(float))
        net.senses_, net.scenes_ = list(senses), list(scenes)
        net.coefs_, net.intercepts_ = coefs, intercepts
        net.threshold_, net.n_rows_, net.flags_ = float(threshold), n_rows, flags
        return net


def leaned_on(
    net: FusionNet,
    opinions: Mapping[str, Pooled],
    scene: str,
) -> tuple[str, ...]:
    """The senses the decision for `scene` leaned on: those whose removal lowers its probability
    by `LEAN_MARGIN` or more, most first; when no single one matters that much (they agree and
    each would do alone), those whose own top scene is `scene`."""
    present = [s for s in net.senses_ if s in opinions]
    if len(present) == 1:
        return (present[0],)
    column = net.scenes_.index(scene)
    whole = float(net.predict_proba(net.features(opinions))[0, column])
    drops = {
        sense: whole
        - float(
            net.predict_proba(net.features({k: v for k, v in opinions.items() if k != sense}))[
                0, column
            ]
        )
        for sense in present
    }
    leaning = sorted((s for s in present if drops[s] >= LEAN_MARGIN), key=lambda s: -drops[s])
    if leaning:
        return tuple(leaning)
    return tuple(
        s
        for s in present
        if opinions[s][0] and max(opinions[s][0], key=lambda k: opinions[s][0][k]) == scene
    )
