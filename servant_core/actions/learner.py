"""The action learner: a small neural network from what the engine perceived to the pose to take.

Inputs: the acoustic then visual scores of every scene in `scenes_`; outputs: the angles of
`joints_`. scikit-learn's `MLPRegressor` on per-joint standardised angles, trained in chunks of
`report_every` iterations so the error is reported as it falls (the paper's Fig. 6). Weights and
biases are saved in an `.npz` with a JSON header (no pickle), and predictions run through
`perceptron.forward`, before and after saving: the arm does exactly what was trained and tested.
"""

from __future__ import annotations

import json
import math
import warnings
import zipfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self

import numpy as np
from sklearn.exceptions import ConvergenceWarning, NotFittedError
from sklearn.neural_network import MLPRegressor
from threadpoolctl import threadpool_limits

from servant_core.actions.records import SENSES, TeachRecord, label_scores
from servant_core.errors import ServantError
from servant_core.numbers import json_loads
from servant_core.perceptron import ACTIVATIONS, forward
from servant_core.recognisers.base import UNKNOWN
from servant_core.storage import (
    atomic_save_npz,
    check_replaceable,
    data_dir,
    is_servant_npz_of,
    os_reason,
)

FORMAT = "servant-action-learner"
VERSION = 1


def default_learner_path() -> Path:
    return data_dir() / "teach" / "learner.npz"


@dataclass(frozen=True)
class ActionPrediction:
    """The pose to take for a decision, or why the arm will not act (`pose` None, `reason` said)."""

    scene: str | None
    pose: dict[str, float] | None
    reason: str | None = None

    @property
    def acted(self) -> bool:
        return self.pose is not None


def check_learner_output(path: str | Path) -> Path:
    """`path` if an action learner may be saved there: not a link, nor a read-only file, nor a
    file of another kind (a model, a document)."""
    path = Path(path)
    check_replaceable(path, "action learner file", is_servant_npz_of(FORMAT))
    return path


class ActionLearner:
    def __init__(
        self,
        hidden_layer_sizes: tuple[int, ...] = (16,),
        activation: str = "tanh",
        max_iter: int = 3000,
        report_every: int = 1000,
        learning_rate_init: float = 0.01,
        confidence_threshold: float = 50.0,
        home: Mapping[str, float] | None = None,
        random_state: int = 0,
    ) -> None:
        self.hidden_layer_sizes = hidden_layer_sizes
        self.activation = activation
        self.max_iter = max_iter
        self.report_every = report_every
        self.learning_rate_init = learning_rate_init
        self.confidence_threshold = confidence_threshold
        self.home = home
        self.random_state = random_state

    def features(self, scores: Mapping[str, Mapping[str, float]]) -> np.ndarray:
        """One input row: each sense's score for each known scene; a missing one counts as 0."""
        self._check_fitted()
        return np.array(
            [
                float(scores.get(sense, {}).get(scene, 0.0))
                for sense in SENSES
                for scene in self.scenes_
            ]
        )

    def fit(
        self, records: Sequence[TeachRecord], report: Callable[[int, float], None] | None = None
    ) -> Self:
        """Learn scene scores -> pose; `report(iterations, error in degrees)` as training goes.

        A joint a record does not set takes its `home` angle there; without one it is an error.
        """
        if len(records) == 0:
            raise ServantError("nothing to learn from: teach at least one scene first")
        if self.activation not in ACTIVATIONS:
            raise ServantError(
                f"activation {self.activation!r} is unknown; use one of {', '.join(ACTIVATIONS)}"
            )
        self.scenes_ = sorted(
            {r.scene for r in records} | {s for r in records for d in r.scores.values() for s in d}
        )
        self.taught_scenes_ = sorted({r.scene for r in records})
        self.joints_ = list(dict.fromkeys(name for r in records for name in r.pose))
        y = _angles(records, self.joints_, self.home or {})
        x = np.array([self.features(r.scores) for r in records])
        self.y_mean_, self.y_scale_, target = _standardised(y)
        net = self._network()
        self.history_: list[tuple[int, float]] = []
        done = 0
        for checkpoint in _checkpoints(self.report_every, self.max_iter):
            net.set_params(max_iter=checkpoint - done)
            # One BLAS thread: these matrices are tiny, and threads fighting over a busy CPU made
            # a 300-scene fit 20 times slower (bench/teach_records.py).
            with warnings.catch_warnings(), threadpool_limits(1, user_api="blas"):
                warnings.simplefilter("ignore", ConvergenceWarning)  # stopping early is the plan
                net.fit(x, target)
            done = checkpoint
            self.coefs_ = [w.copy() for w in net.coefs_]
            self.intercepts_ = [b.copy() for b in net.intercepts_]
            error = float(np.mean(np.abs(self._poses(x) - y)))
            self.history_.append((done, error))
            if report is not None:
                report(done, error)
        self.n_records_ = len(records)
        return self

    def _network(self) -> MLPRegressor:
        """The network `fit` trains a chunk at a time (`warm_start`), never stopping on its own:
        it runs for exactly `max_iter` iterations, whose error is the report."""
        return MLPRegressor(
            hidden_layer_sizes=self.hidden_layer_sizes,
            activation=self.activation,
            learning_rate_init=self.learning_rate_init,
            tol=0.0,
            n_iter_no_change=self.max_iter + 1,
            warm_start=True,
            random_state=self.random_state,
        )

    def _check_fitted(self) -> None:
        if not hasattr(self, "scenes_"):
            raise NotFittedError("this ActionLearner has not been fitted; call fit(records) first")

    def _poses(self, x: np.ndarray) -> np.ndarray:
        return (
            forward(x, self.coefs_, self.intercepts_, self.activation) * self.y_scale_
            + self.y_mean_
        )

    def pose(self, scores: Mapping[str, Mapping[str, float]]) -> dict[str, float]:
        """The pose the network gives for `scores`, without the safety checks of `predict`."""
        row = self._poses(self.features(scores)[None, :])[0]
        return {joint: float(angle) for joint, angle in zip(self.joints_, row, strict=True)}

    def predict(
        self, scores: Mapping[str, Mapping[str, float]], scene: str | None, confidence: float
    ) -> ActionPrediction:
        """The pose for `scene`; refused for no scene, an untaught one or low confidence."""
        self._check_fitted()
        if scene is None or scene == UNKNOWN:
            return ActionPrediction(scene, None, "no scene was recognised, so the arm stays put")
        if scene not in self.taught_scenes_:
            return ActionPrediction(
                scene, None, f"I was never taught what to do in {scene!r}; teach it first"
            )
        if not (math.isfinite(confidence) and confidence >= self.confidence_threshold):
            return ActionPrediction(
                scene,
                None,
                f"confidence {confidence:.1f}% is under the threshold of "
                f"{self.confidence_threshold:g}%, "
                "so the arm stays put",
            )
        return ActionPrediction(scene, self.pose(scores))

    def pose_for(
        self,
        scene: str,
        scores: Mapping[str, Mapping[str, float]] | None = None,
        confidence: float = 100.0,
    ) -> dict[str, float]:
        """`predict` for a caller that wants a pose or an error (the engine's action hook).

        Without `scores`, the scene counts as certain (one-hot, as a typed label). A refusal is
        raised as a ServantError carrying its reason.
        """
        self._check_fitted()
        prediction = self.predict(scores or label_scores(scene, self.scenes_), scene, confidence)
        if prediction.pose is None:
            raise ServantError(f"arm: {prediction.reason}")
        return prediction.pose

    # -- files ------------------------------------------------------------------------------

    def save(self, path: str | Path | None = None) -> Path:
        self._check_fitted()
        path = Path(path) if path is not None else default_learner_path()
        header: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "params": {
                "hidden_layer_sizes": list(self.hidden_layer_sizes),
                "activation": self.activation,
                "max_iter": self.max_iter,
                "report_every": self.report_every,
                "learning_rate_init": self.learning_rate_init,
                "confidence_threshold": self.confidence_threshold,
                "home": dict(self.home) if self.home else None,
                "random_state": self.random_state,
            },
            "scenes": self.scenes_,
            "taught_scenes": self.taught_scenes_,
            "joints": self.joints_,
            "history": self.history_,
            "n_records": self.n_records_,
        }
        check_learner_output(path)
        arrays = {f"coef_{i}": w for i, w in enumerate(self.coefs_)}
        arrays |= {f"intercept_{i}": b for i, b in enumerate(self.intercepts_)}
        arrays |= {
            "y_mean": self.y_mean_,
            "y_scale": self.y_scale_,
            "header": np.array(json.dumps(header)),
        }
        try:
            return atomic_save_npz(path, arrays)
        except OSError as exc:
            raise ServantError(
                f"{path}: cannot save the action learner ({os_reason(exc)}); the previous file "
                "is unchanged; check that its folder can be written to and has space"
            ) from None

    @classmethod
    def load(cls, path: str | Path | None = None) -> ActionLearner:
        path = Path(path) if path is not None else default_learner_path()
        if not path.is_file():
            raise ServantError(
                f"{path}: no trained action learner; teach the arm with `servant teach`"
            )
        try:
            with np.load(path, allow_pickle=False) as npz:
                arrays = {name: npz[name] for name in npz.files}
            header = json_loads(str(arrays.pop("header")))
            fmt, version = header["format"], header["version"]
        except (
            OSError,
            ValueError,
            KeyError,
            TypeError,
            RecursionError,
            zipfile.BadZipFile,
            EOFError,
        ) as exc:
            raise ServantError(
                f"{path}: not a Servant action learner (corrupt or another format)"
            ) from exc
        if fmt != FORMAT:
            raise ServantError(f"{path}: not a Servant action learner (format {fmt!r})")
        if version != VERSION:
            raise ServantError(
                f"{path}: action learner version {version!r} is not {VERSION}; "
                "retrain with `servant teach`"
            )
        try:
            params = header["params"]
            learner = cls(**{**params, "hidden_layer_sizes": tuple(params["hidden_layer_sizes"])})
            layers = len(learner.hidden_layer_sizes) + 1
            learner.coefs_ = [arrays[f"coef_{i}"] for i in range(layers)]
            learner.intercepts_ = [arrays[f"intercept_{i}"] for i in range(layers)]
            learner.y_mean_, learner.y_scale_ = arrays["y_mean"], arrays["y_scale"]
            learner.scenes_ = list(header["scenes"])
            learner.taught_scenes_ = list(header["taught_scenes"])
            learner.joints_ = list(header["joints"])
            learner.history_ = [(int(i), float(e)) for i, e in header["history"]]
            learner.n_records_ = int(header["n_records"])
            if learner.coefs_[0].shape[0] != len(SENSES) * len(learner.scenes_):
                raise ValueError("input size does not match the scenes")
            if learner.coefs_[-1].shape[1] != len(learner.joints_):
                raise ValueError("output size does not match the joints")
        except (KeyError, ValueError, TypeError) as exc:
            raise ServantError(
                f"{path}: damaged action learner ({exc}); retrain with `servant teach`"
            ) from exc
        return learner


def _angles(
    records: Sequence[TeachRecord], joints: Sequence[str], home: Mapping[str, float]
) -> np.ndarray:
    """The taught angles, a row per record and a column per joint: a joint a record does not set
    takes its `home` angle; without one it is a ServantError naming the record."""
    y = np.empty((len(records), len(joints)))
    for i, record in enumerate(records):
        for j, joint in enumerate(joints):
            if joint in record.pose:
                y[i, j] = record.pose[joint]
            elif joint in home:
                y[i, j] = home[joint]
            else:
                raise ServantError(
                    f"teach record {i + 1} ({record.scene}) has no angle for joint {joint!r}; "
                    "teach it again with a full pose"
                )
    return y


def _standardised(y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean, scale, target): the angles standardised per joint (a joint that never moves keeps
    a scale of 1), 1-d for a single joint, as scikit-learn wants a single output."""
    mean = y.mean(axis=0)
    spread = y.std(axis=0)
    scale = np.where(spread > 0, spread, 1.0)
    target = (y - mean) / scale
    if target.shape[1] == 1:
        target = target.ravel()
    return mean, scale, target


def _checkpoints(report_every: int, max_iter: int) -> list[int]:
    """The iteration counts at which `fit` reports: after the first, every `report_every`, and
    at `max_iter`."""
    checkpoints = [1, *range(report_every, max_iter + 1, report_every)]
    if checkpoints[-1] != max_iter:
        checkpoints.append(max_iter)
    return checkpoints
