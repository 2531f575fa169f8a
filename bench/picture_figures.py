"""Do the pictures' figures (`× average`) mean what they say, taught six pictures a place?

For each library size and draw, `--pictures` pictures of each taught picture scene are taught to
`fisher-bovw` (as teach mode and `bench/picture_open_set.py` teach them); then other pictures
are shown with the figure the user reads beside a sound that knows somewhere else: how many
times likelier the picture makes a place than the average taught place (K·p, `likelier` in
`fusion/elsewhere.py`). Medians over every draw's pictures of:

- (a) own: other pictures of a taught place's kind, under their own place (should be above 1);
- (b) other taught: the same pictures under each other taught place (should be below 1);
- (c) untaught, largest: pictures of scenes not taught, their largest figure over the places
  (pictures know no elsewhere: this says how loudly they speak of a place never shown them).

Beside them, the same pictures' log loss among the taught places (−log p of their own place:
lower is better, log K is a coin toss) and how often the likeliest place is theirs.

"before" is the regularisation chosen as it was until issue 38 (balanced accuracy of folds of
the head's own rows, one standard error toward the smallest C of 0.003 … 1), recomputed here on
the same model and refitted; "after" is the model as `fit` leaves it. The fit time of twelve
pictures (the first draw of two places) is measured both ways: "before" is a fit with C given
plus that old choice.

    OMP_NUM_THREADS=1 python bench/picture_figures.py [--sizes 2,3,5] [--draws 6]
        [--pictures 6] [--seed 0]
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import balanced_accuracy_score
from sklearn.model_selection import StratifiedKFold

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import shared_data  # noqa: E402
from bench.picture_open_set import TESTED  # noqa: E402
from servant_core.library import read_picture  # noqa: E402
from servant_core.recognisers import make_recogniser  # noqa: E402
from servant_core.recognisers.softbovw import one_standard_error_choice  # noqa: E402

OLD_C_GRID = (0.003, 0.01, 0.03, 0.1, 0.3, 1.0)


def old_choice(model: Any, n_pictures: int, folds: int = 4) -> float:
    """The C chosen before issue 38: stratified folds of the head's training rows (a picture
    and its mirror on the same side), balanced accuracy, the smallest C within one standard
    error of the best."""
    rows, labels = model.train_rows_, model.train_scenes_
    pictures = labels[:n_pictures]
    folds = min(folds, int(min(np.unique(pictures, return_counts=True)[1])))
    scores = np.zeros((len(OLD_C_GRID), folds))
    cv = StratifiedKFold(folds, shuffle=True, random_state=model.random_state)
    for k, (train, test) in enumerate(cv.split(pictures, pictures)):
        fold = np.concatenate([train + c * n_pictures for c in range(len(labels) // n_pictures)])
        for i, C in enumerate(OLD_C_GRID):
            head = LogisticRegression(C=C, class_weight="balanced", max_iter=3000)
            head.fit(rows[fold], labels[fold])
            scores[i, k] = balanced_accuracy_score(pictures[test], head.predict(rows[test]))
    return float(OLD_C_GRID[one_standard_error_choice(scores)])


def as_before(model: Any, n_pictures: int) -> Any:
    """A copy of `model` with its head refitted at the C chosen the old way."""
    before = copy.deepcopy(model)
    before.C_ = old_choice(model, n_pictures)
    before._fit_head()
    return before


def figures(model: Any, X: np.ndarray, truth: np.ndarray, untaught: np.ndarray) -> dict:
    """The figures of one model: per-picture lists, pooled over draws by the caller."""
    proba = model.predict_proba(X[: len(truth)])
    K = len(model.scenes_)
    column = np.searchsorted(model.scenes_, truth)
    own = proba[np.arange(len(truth)), column]
    others = np.delete(proba, np.ravel_multi_index((np.arange(len(truth)), column), proba.shape))
    return {
        "own": list(K * own),
        "other taught": list(K * others),
        "untaught, largest": list(K * model.predict_proba(untaught).max(axis=1)),
        "log loss": list(-np.log(np.clip(own, 1e-12, None))),
        "named rightly": list(proba.argmax(axis=1) == column),
        "C": [model.C_],
    }


def one_draw(X: np.ndarray, scenes: np.ndarray, size: int, pictures: int, rng: Any, method: str):
    kinds = [str(k) for k in rng.permutation(sorted(set(scenes)))]
    taught = kinds[:size]
    train, same_kind, untaught = [], [], []
    for kind in sorted(set(scenes)):
        rows = rng.permutation(np.flatnonzero(scenes == kind))
        if kind in taught:
            train += list(rows[:pictures])
            same_kind += list(rows[pictures : pictures + TESTED])
        else:
            untaught += list(rows[:TESTED])
    started = time.thread_time()
    after = make_recogniser("image", method).fit(X[train], scenes[train])
    fit_after = time.thread_time() - started
    truth = scenes[same_kind]
    result = {"after": figures(after, X[same_kind], truth, X[untaught])}
    if method == "fisher-bovw":  # "before" is fisher-bovw's old choice of C
        result["before"] = figures(as_before(after, len(train)), X[same_kind], truth, X[untaught])
    return taught, train, result, fit_after


def fit_before(X: np.ndarray, scenes: np.ndarray, train: list) -> float:
    """CPU seconds of a fit as it was: with C given (no new choice), then the old choice."""
    started = time.thread_time()
    model = make_recogniser("image", "fisher-bovw", C=1.0).fit(X[train], scenes[train])
    old_choice(model, len(train))
    return time.thread_time() - started


def report(size: int, pooled: dict) -> None:
    print(f"{size} places taught (medians; log loss and named rightly: means):")
    for name in ("own", "other taught", "untaught, largest", "log loss", "named rightly", "C"):
        middle = np.mean if name in ("log loss", "named rightly") else np.median
        whens = [when for when in ("before", "after") if when in pooled]
        cells = "   ".join(f"{when} {middle(pooled[when][name]):6.3f}" for when in whens)
        extra = ""
        if name == "C":
            extra = "   chosen: " + " / ".join(
                ",".join(f"{c:g}" for c in pooled[when]["C"]) for when in whens
            )
        print(f"  {name:<20} {cells}{extra}")
    print(f"  (coin toss log loss: {np.log(size):.3f})", flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data())
    parser.add_argument("--sizes", default="2,3,5")
    parser.add_argument("--draws", type=int, default=6)
    parser.add_argument("--pictures", type=int, default=6, help="pictures taught a place")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--method", default="fisher-bovw", help="the picture method taught")
    args = parser.parse_args()
    root = args.data / "images" / "dev"
    if not root.is_dir():
        print(f"no real pictures at {root}; nothing to measure")
        return 0
    paths = sorted(p for folder in sorted(root.iterdir()) for p in sorted(folder.iterdir()))
    scenes = np.array([p.parent.name for p in paths])
    X = make_recogniser("image", args.method).featurize([read_picture(p) for p in paths])
    print(
        f"{len(paths)} pictures of {len(set(scenes))} scenes; {args.pictures} taught a place, "
        f"{TESTED} tested a scene, {args.draws} draws a size, seed {args.seed}, {args.method}"
    )
    for size in [int(s) for s in args.sizes.split(",")]:
        pooled: dict = defaultdict(lambda: defaultdict(list))
        for draw in range(args.draws):
            rng = np.random.default_rng([args.seed, size, draw])
            taught, train, result, fit_after = one_draw(
                X, scenes, size, args.pictures, rng, args.method
            )
            print(f"  {size} places, draw {draw}: {', '.join(taught)}", flush=True)
            if draw == 0 and args.method == "fisher-bovw":
                print(
                    f"  fit of {len(train)} pictures, CPU seconds: before "
                    f"{fit_before(X, scenes, train):.1f}, after {fit_after:.1f}"
                )
            for when, values in result.items():
                for name, value in values.items():
                    pooled[when][name] += value
        report(size, pooled)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
