"""Servant's picture methods beside plain, well-known ones, on the same pictures and split.

The split is `eval image`'s: the first 70 % of each scene's pictures by file name train, the rest
test (`servant_core.evaluate.file_order_split`). Peers, each with its parameters chosen by
stratified cross-validation inside the training pictures:

- HSV histogram (8 × 4 × 4, square-rooted) + RBF SVM (C and γ by cross-validation);
- HOG + HSV + linear SVM: the gradient-orientation blocks of `features.descriptors` (8×8-pixel
  cells, 2×2-cell blocks, unit length: a small HOG) side by side with the HSV histogram; C by
  cross-validation;
- Servant's `bovw`, `softbovw`, `fisher-bovw` and `effnet`, as `servant eval image --method M`
  runs them.

What one 640×480 camera frame costs each of Servant's methods (features, probabilities,
decision; median of 30) is given twice: wall time, and CPU time (`time.process_time`), which
other work on a shared machine does not inflate.

A peer decides by its SVM; its probabilities (for the log loss) come from a sigmoid calibration
of the chosen SVM on folds of the training pictures.

Every method runs once per random state 0 … seeds − 1 (K-Means, SVM and fold shuffles); a row
holds the mean and the spread (standard deviation) of balanced accuracy over them.

    python bench/picture_peers.py [--data ../shared/data] [--seeds 1]

`picture_rows(data_root, seeds)` is what `bench/peers.py` appends to its table.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from sklearn.base import clone
from sklearn.calibration import CalibratedClassifierCV
from sklearn.metrics import accuracy_score, balanced_accuracy_score
from sklearn.model_selection import GridSearchCV, StratifiedKFold
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC, LinearSVC

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from common import median_ms, shared_data  # noqa: E402

from servant_core.evaluate import IMAGE_TRAIN_FRACTION, file_order_split  # noqa: E402
from servant_core.features.descriptors import block_descriptors, hsv_histogram  # noqa: E402
from servant_core.library import SceneLibrary, read_pictures  # noqa: E402
from servant_core.recognisers import make_recogniser  # noqa: E402

SERVANT_METHODS = ("bovw", "softbovw", "fisher-bovw", "effnet")
CV_FOLDS = 4
LOG_EPS = 1e-15


def picture_library(data_root: Path) -> Path:
    """`data_root/images/dev` when `data_root` is the shared data folder, else `data_root`."""
    nested = Path(data_root) / "images" / "dev"
    return nested if nested.is_dir() else Path(data_root)


def hsv_rows(images: list[np.ndarray]) -> np.ndarray:
    return np.sqrt(np.array([hsv_histogram(image) for image in images]))


def hog_hsv_rows(images: list[np.ndarray]) -> np.ndarray:
    hog = np.array([block_descriptors(image)[0].ravel() for image in images])
    return np.hstack([hog, hsv_rows(images)])


def calibrated(estimator: Any) -> Any:
    # SVMs give no probabilities; a sigmoid fitted on held-out folds of the training part does
    return CalibratedClassifierCV(clone(estimator), cv=3, method="sigmoid", ensemble=False)


def hsv_svm(seed: int) -> Any:
    folds = StratifiedKFold(CV_FOLDS, shuffle=True, random_state=seed)
    pipeline = make_pipeline(StandardScaler(), SVC(class_weight="balanced"))
    grid = {"svc__C": [1, 10, 100], "svc__gamma": ["scale", 0.01, 0.001]}
    return GridSearchCV(pipeline, grid, cv=folds, scoring="balanced_accuracy")


def hog_hsv_linear_svm(seed: int) -> Any:
    folds = StratifiedKFold(CV_FOLDS, shuffle=True, random_state=seed)
    svm = LinearSVC(class_weight="balanced", random_state=seed)
    pipeline = make_pipeline(StandardScaler(), svm)
    grid = {"linearsvc__C": [1e-4, 1e-3, 1e-2]}
    return GridSearchCV(pipeline, grid, cv=folds, scoring="balanced_accuracy")


PEERS: dict[str, tuple[Callable[[list[np.ndarray]], np.ndarray], Callable[[int], Any]]] = {
    "HSV histogram + RBF SVM": (hsv_rows, hsv_svm),
    "HOG + HSV + linear SVM": (hog_hsv_rows, hog_hsv_linear_svm),
}


def figures(truth: np.ndarray, proba: np.ndarray, predicted: np.ndarray, columns: list[str]):
    p_truth = proba[np.arange(len(truth)), [columns.index(t) for t in truth]]
    return (
        balanced_accuracy_score(truth, predicted),
        accuracy_score(truth, predicted),
        float(-np.mean(np.log(np.clip(p_truth, LOG_EPS, 1.0)))),
    )


def row(method: str, protocol: str, runs: list[tuple[float, float, float]]) -> dict[str, Any]:
    values = np.array(runs)
    return {
        "method": method,
        "protocol": protocol,
        "balanced_accuracy": float(values[:, 0].mean()),
        "accuracy": float(values[:, 1].mean()),
        "log_loss": float(values[:, 2].mean()),
        "spread": float(values[:, 0].std()),
    }


def one_frame(model: Any, frame: np.ndarray) -> np.ndarray:
    X = model.featurize([frame])
    model.predict_proba(X)
    return model.predict(X)


def picture_rows(data_root: Path, seeds: int = 1) -> list[dict[str, Any]]:
    """One row per method on the file-order 70/30 split of the picture library."""
    library = SceneLibrary.scan(picture_library(data_root))
    images, kept = read_pictures(library.pictures)
    train = file_order_split(kept, IMAGE_TRAIN_FRACTION)
    scenes = np.array([p.scene for p in kept])
    protocol = f"file-order-{IMAGE_TRAIN_FRACTION:g}, {len(set(scenes.tolist()))} scenes"
    rows = []
    for name, (featurize, make) in PEERS.items():
        X = featurize(images)
        runs = []
        for seed in range(seeds):
            model = make(seed).fit(X[train], scenes[train])
            # decisions are the SVM's own; probabilities (for the log loss) from its calibration
            proba = calibrated(model.best_estimator_).fit(X[train], scenes[train])
            runs.append(
                figures(
                    scenes[~train],
                    proba.predict_proba(X[~train]),
                    model.predict(X[~train]),
                    list(proba.classes_),
                )
            )
        rows.append(row(name, protocol, runs))
    for method in SERVANT_METHODS:
        X = make_recogniser("image", method).featurize(images)
        runs = []
        for seed in range(seeds):
            model = make_recogniser("image", method, random_state=seed)
            model.fit(X[train], scenes[train])
            runs.append(
                figures(
                    scenes[~train],
                    model.predict_proba(X[~train]),
                    model.predict(X[~train]),
                    list(model.scenes_),
                )
            )
        rows.append(row(method, protocol, runs))
        # what one camera frame costs the last fitted model: features, probabilities, decision
        frame = cv2.resize(images[int(np.flatnonzero(~train)[0])], (640, 480))
        rows[-1]["ms_per_frame"] = median_ms(lambda m=model, f=frame: one_frame(m, f))
        rows[-1]["cpu_ms_per_frame"] = median_ms(
            lambda m=model, f=frame: one_frame(m, f), clock=time.process_time
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data(), help="data or picture root")
    parser.add_argument("--seeds", type=int, default=1, help="random states per method")
    args = parser.parse_args()
    rows = picture_rows(args.data, args.seeds)
    print(f"pictures: {picture_library(args.data)}, {rows[0]['protocol']}, seeds {args.seeds}")
    print(
        f"{'method':<26} {'balanced':>9} {'spread':>7} {'accuracy':>9} {'log loss':>9}"
        f" {'ms/frame':>9} {'CPU ms':>7}"
    )
    for r in rows:
        print(
            f"{r['method']:<26} {r['balanced_accuracy']:>9.3f} {r['spread']:>7.3f}"
            f" {r['accuracy']:>9.3f} {r['log_loss']:>9.2f}"
            + (f" {r['ms_per_frame']:>9.1f}" if "ms_per_frame" in r else "")
            + (f" {r['cpu_ms_per_frame']:>7.1f}" if "cpu_ms_per_frame" in r else "")
        )


if __name__ == "__main__":
    main()
