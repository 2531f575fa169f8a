"""Does projecting out how sources differ help a place never heard? (issue 23, one idea)

Nuisance attribute projection (NAP, from speaker verification's channel compensation): inside
the training windows, each (scene, source) pair's mean descriptor minus its scene's mean is how
that source colours the scene (its microphone, its mixing); the top `k` principal directions of
those differences are projected out of every descriptor before the head, so the head cannot lean
on them. `k` (0 = the plain peer) and C are chosen together by cross-validation grouped by source
inside each fold's training windows (`GroupKFold`, 3 folds), as `bench/peers.py` chooses the
peers' C.

Scored on `bench/peers.py`'s log-mel(64) mean/std descriptors, through the same windows and
folds (`evaluate_windows`) as its rows: `source` (leave one source out) and, with `--protocols`,
`recording`, over the scenes with at least three recordings.

    OMP_NUM_THREADS=1 python bench/source_nuisance.py [--data ../shared/data]
        [--protocols source,recording] [--ks 0,2,4,8,16]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from collections import Counter
from pathlib import Path
from typing import Self

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import GridSearchCV, GroupKFold
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import shared_data  # noqa: E402
from peers import (  # noqa: E402
    INNER_FOLDS,
    featurize_all,
    logmel_stats,
    protocol_plans,
    restricted,
    with_source_column,
)

from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.evaluate import evaluate_windows  # noqa: E402
from servant_core.library import SceneLibrary  # noqa: E402
from servant_core.recognisers.base import TaughtPlacesOnly  # noqa: E402


def nuisance_directions(
    X: np.ndarray, scenes: np.ndarray, sources: np.ndarray, k: int
) -> np.ndarray:
    """(k', d) orthonormal rows: the top principal directions of the (scene, source) means
    minus their scene's mean (k' ≤ k: no more than the differences span)."""
    rows = []
    for scene in np.unique(scenes):
        in_scene = scenes == scene
        means = [X[in_scene & (sources == s)].mean(axis=0) for s in np.unique(sources[in_scene])]
        if len(means) > 1:
            rows += list(np.array(means) - np.mean(means, axis=0))
    if k == 0 or not rows:
        return np.zeros((0, X.shape[1]))
    _, values, vt = np.linalg.svd(np.array(rows), full_matrices=False)
    keep = min(k, int(np.sum(values > 1e-9 * values[0])))
    return vt[:keep]


class SourceProjection(TransformerMixin, BaseEstimator):
    """Standardise, then project out the top `k` source directions. Its input carries the
    source's number in a last column, which it reads in `fit` and strips always."""

    def __init__(self, k: int = 0) -> None:
        self.k = k

    def fit(self, X: np.ndarray, y: np.ndarray) -> Self:
        features, sources = X[:, :-1], X[:, -1]
        self.scaler_ = StandardScaler().fit(features)
        z = self.scaler_.transform(features)
        self.directions_ = nuisance_directions(z, np.asarray(y), sources, self.k)
        return self

    def transform(self, X: np.ndarray) -> np.ndarray:
        z = self.scaler_.transform(X[:, :-1])
        return z - (z @ self.directions_.T) @ self.directions_


class NapPeer(TaughtPlacesOnly):
    """log-mel + NAP + logistic regression; k and C by CV grouped by source (last column)."""

    def __init__(self, ks: list[int]) -> None:
        self.ks = ks

    def fit(self, X: np.ndarray, scenes: np.ndarray) -> Self:
        groups = X[:, -1]
        pipeline = make_pipeline(
            SourceProjection(),
            StandardScaler(),
            LogisticRegression(class_weight="balanced", max_iter=3000),
        )
        grid = {
            "sourceprojection__k": self.ks,
            "logisticregression__C": [0.01, 0.1, 1.0],
        }
        folds = min(INNER_FOLDS, len(np.unique(groups)))
        search = GridSearchCV(pipeline, grid, cv=GroupKFold(folds), scoring="balanced_accuracy")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.model_ = search.fit(X, scenes, groups=groups).best_estimator_
        self.chosen_ = search.best_params_
        return self

    @property
    def scenes_(self) -> list[str]:
        return [str(s) for s in self.model_.classes_]

    def predict(self, X: np.ndarray) -> np.ndarray:
        return self.model_.predict(X)

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        return self.model_.predict_proba(X)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data(), help="the shared data root")
    parser.add_argument("--protocols", type=lambda t: tuple(t.split(",")), default=("source",))
    parser.add_argument(
        "--ks", type=lambda t: [int(k) for k in t.split(",")], default=[0, 2, 4, 8, 16]
    )
    args = parser.parse_args()
    library = SceneLibrary.scan(args.data / "audio" / "dev")
    wf = with_source_column(featurize_all(library, {"logmel": logmel_stats})["logmel"])
    names = [str(r.path.relative_to(library.root)) for r in library.recordings]
    made: list[NapPeer] = []  # every fold's peer, to read what its search chose

    def make(ks: list[int]) -> NapPeer:
        made.append(NapPeer(ks))
        return made[-1]

    for column, keep, plans in protocol_plans(wf, args.protocols):
        for label, ks in (("log-mel + LR (k 0)", [0]), (f"+ NAP (k of {args.ks})", args.ks)):
            made.clear()
            start = time.perf_counter()
            (row,) = evaluate_windows(restricted(wf, keep), names, plans, lambda _, ks=ks: make(ks))
            picks = Counter(p.chosen_["sourceprojection__k"] for p in made if hasattr(p, "chosen_"))
            print(
                f"{column:<10} {label:<28} {row['balanced_accuracy']:.3f}  log loss "
                f"{row['log_loss']:.2f}  k chosen {dict(sorted(picks.items()))} "
                f"({time.perf_counter() - start:.0f} s)",
                flush=True,
            )


if __name__ == "__main__":
    with library_noise_silenced():  # mpg123 warns of one real MP3 on descriptor 2
        main()
