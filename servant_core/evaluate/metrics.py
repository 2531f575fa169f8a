"""What a test scores: pooled predictions, their figures, and figures over random states.

`scores` gives accuracy, balanced accuracy, per-scene recall, log loss, the unknown and
elsewhere rates and the confusion matrix; `over_seeds` runs a protocol over random states and
gives each figure's mean and spread beside every seed's own.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sklearn.metrics import confusion_matrix

from servant_core.errors import ServantError
from servant_core.recognisers import UNKNOWN, Recogniser, methods_for
from servant_core.recognisers.base import open_predict

LOG_EPS = 1e-15
SEED_METRICS = ("accuracy", "balanced_accuracy", "log_loss", "unknown_rate", "elsewhere_rate")


@dataclass
class Predictions:
    """Pooled test predictions: true scene, predicted scene, probability given to the truth."""

    truth: list[str]
    predicted: list[str]
    p_truth: list[float]
    # where the open set says "somewhere else" (`open_predict`) though a taught place was named
    elsewhere: list[bool] = field(default_factory=list)

    def extend(self, model: Recogniser, X: np.ndarray, truth: Sequence[str]) -> None:
        if len(X) == 0:  # nothing of this fold to test (`scores` says so if nothing at all is)
            return
        predicted = model.predict(X)
        opened = open_predict(model, X)
        proba = model.predict_proba(X)
        column = {s: j for j, s in enumerate(model.scenes_)}
        for i, scene in enumerate(truth):
            self.truth.append(str(scene))
            self.predicted.append(str(predicted[i]))
            self.elsewhere.append(bool(opened[i] == UNKNOWN and predicted[i] != UNKNOWN))
            j = column.get(str(scene))
            self.p_truth.append(float(proba[i, j]) if j is not None else 0.0)


def scores(preds: Predictions, scenes: Sequence[str]) -> dict[str, Any]:
    """accuracy, balanced accuracy, per-scene recall, log loss, unknown rate, confusion matrix."""
    truth = np.array(preds.truth)
    predicted = np.array(preds.predicted)
    if len(truth) == 0:
        raise ServantError("nothing to evaluate: no test window or picture")
    present = [s for s in scenes if s in set(truth.tolist())]
    # balanced accuracy = mean recall over the scenes that occur in the test set
    recall = {s: float(np.mean(predicted[truth == s] == s)) for s in present}
    labels = [*scenes, UNKNOWN]
    p = np.clip(np.array(preds.p_truth), LOG_EPS, 1.0)
    return {
        "accuracy": float(np.mean(truth == predicted)),
        "balanced_accuracy": float(np.mean(list(recall.values()))),
        "per_class": recall,
        "log_loss": float(-np.mean(np.log(p))),
        "unknown_rate": float(np.mean(predicted == UNKNOWN)),
        # the open set's cost: windows of taught places it would call somewhere else
        "elsewhere_rate": float(np.mean(preds.elsewhere)) if preds.elsewhere else 0.0,
        "n_test": int(len(truth)),
        "confusion": {
            "labels": labels,
            "matrix": confusion_matrix(truth, predicted, labels=labels).tolist(),
        },
    }


def per_recording(
    preds: Predictions, recording: np.ndarray, names: Sequence[str]
) -> dict[str, dict[str, Any]]:
    """Per test recording: its scene, the share of its windows named right, and what its windows
    were heard as (a whole recording taken for another scene shows here, not in the averages)."""
    truth, predicted = np.array(preds.truth), np.array(preds.predicted)
    result = {}
    for r in np.unique(recording):
        rows = recording == r
        heard, counts = np.unique(predicted[rows], return_counts=True)
        most_first = np.argsort(-counts, kind="stable")
        result[names[r]] = {
            "scene": str(truth[rows][0]),
            "recall": float(np.mean(predicted[rows] == truth[rows])),
            "heard_as": {str(heard[i]): int(counts[i]) for i in most_first},
        }
    return result


def seeded_params(
    cls_params: dict[str, Any], method: str, sense: str, seed: int | None
) -> dict[str, Any]:
    """`cls_params` with `random_state=seed` when the method takes one (seed None: as given)."""
    if seed is None:
        return cls_params
    init = inspect.signature(methods_for(sense)[method].__init__).parameters
    return {**cls_params, "random_state": seed} if "random_state" in init else cls_params


def over_seeds(run: Callable[[int | None], dict[str, Any]], seeds: int) -> dict[str, Any]:
    """`run(None)` once (the method's own random state) when `seeds` is 1; otherwise
    `run(0..seeds-1)`, and the result holds the mean of each figure, its spread (std, min, max)
    and every seed's own figures under `per_seed`."""
    if seeds < 1:
        raise ServantError(f"--seeds must be at least 1, not {seeds}")
    if seeds == 1:
        return run(None)
    runs = [run(seed) for seed in range(seeds)]
    result = dict(runs[0])
    # What one seed heard recording by recording does not average; each seed's figures are kept.
    for key in ("per_recording", "confusion"):
        result.pop(key, None)
    result["per_class"] = {
        scene: float(np.mean([r["per_class"][scene] for r in runs]))
        for scene in result["per_class"]
    }
    averaged(result, runs, SEED_METRICS)
    result["seeds"] = seeds
    result["per_seed"] = [
        {"random_state": seed, **{key: r[key] for key in (*SEED_METRICS, "per_class")}}
        for seed, r in enumerate(runs)
    ]
    return result


def averaged(
    result: dict[str, Any], runs: Sequence[Mapping[str, Any]], keys: Sequence[str]
) -> None:
    """Each figure of `keys` in `result` becomes its mean over `runs`, with its spread (std,
    min, max) under `result["spread"]`."""
    result["spread"] = {}
    for key in keys:
        values = np.array([r[key] for r in runs])
        result[key] = float(values.mean())
        result["spread"][key] = {
            "std": float(values.std()),
            "min": float(values.min()),
            "max": float(values.max()),
        }
