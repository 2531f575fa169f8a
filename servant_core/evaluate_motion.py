"""How well the motion and ambient senses recognise scenes: on synthesised windows, and on a
folder of recorded CSV logs (`ROOT/<scene>/*.imu.csv`, `*.ambient.csv`).

No real labelled motion or ambient data is at hand: the synthesised figures measure the method
on the demo's own signals, and `evaluate_library` is ready for a real data set. The score is
balanced accuracy (the mean of the per-scene recalls) with "unknown" counted as a miss, beside
the decision rate (share of windows named at all) and the precision of the named ones.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sklearn.model_selection import StratifiedGroupKFold

from servant_core.capture.sample_files import SUFFIXES, cut_sample_windows, read_samples
from servant_core.demo.motion_synth import SCENE_AMBIENT, SCENE_MOTION, synth_ambient, synth_motion
from servant_core.errors import ServantError
from servant_core.recognisers import UNKNOWN, make_recogniser
from servant_core.recognisers.sensor_centroids import SensorCentroidRecogniser

SENSE_KIND = {"motion": "imu", "ambient": "ambient"}  # the sense, and its sensor stream
EVAL_STREAMS = {"train": 5, "test": 6}  # seed words: training and test windows never coincide


@dataclass(frozen=True)
class SenseScore:
    balanced_accuracy: float
    decision_rate: float
    precision: float
    n_windows: int


def score(truth: Sequence[str] | np.ndarray, predicted: Sequence[str] | np.ndarray) -> SenseScore:
    """Balanced accuracy with `UNKNOWN` a miss, decision rate, precision of the named windows."""
    truth_arr, predicted_arr = np.asarray(truth), np.asarray(predicted)
    recalls = [np.mean(predicted_arr[truth_arr == s] == s) for s in np.unique(truth_arr)]
    named = predicted_arr != UNKNOWN
    precision = float(np.mean(predicted_arr[named] == truth_arr[named])) if named.any() else 0.0
    return SenseScore(float(np.mean(recalls)), float(np.mean(named)), precision, len(truth_arr))


def new_recogniser(sense: str, seed: int) -> SensorCentroidRecogniser:
    model = make_recogniser(sense, "kmeans", random_state=seed)
    assert isinstance(model, SensorCentroidRecogniser)
    return model


def synthesised_windows(
    sense: str, seed: int, windows_per_scene: int, stream: int
) -> tuple[list[np.ndarray], list[str]]:
    """Windows of every synthesised scene (the demo's three and a vehicle), seeded."""
    scenes = sorted(SCENE_MOTION if sense == "motion" else SCENE_AMBIENT)
    windows, labels = [], []
    for s, scene in enumerate(scenes):
        for i in range(windows_per_scene):
            rng = np.random.default_rng([seed, stream, s, i])
            make = synth_motion if sense == "motion" else synth_ambient
            windows.append(make(scene, rng))
            labels.append(scene)
    return windows, labels


def evaluate_synthesised(sense: str, seed: int, windows_per_scene: int = 20) -> SenseScore:
    """Train on one seeded set of synthesised windows, test on another."""
    train, train_scenes = synthesised_windows(sense, seed, windows_per_scene, EVAL_STREAMS["train"])
    test, test_scenes = synthesised_windows(sense, seed, windows_per_scene, EVAL_STREAMS["test"])
    model = new_recogniser(sense, seed)
    model.fit(model.featurize(train), train_scenes)
    return score(test_scenes, model.predict(model.featurize(test)))


@dataclass
class LibraryWindows:
    windows: list[np.ndarray]
    scenes: list[str]
    groups: list[int]  # the file each window comes from: folds never split a file
    skipped: list[str]  # one line per file that could not be read


def library_windows(root: str | Path, sense: str, rate: int) -> LibraryWindows:
    """The windows of every `ROOT/<scene>/*.imu.csv` (motion) or `*.ambient.csv` file."""
    root = Path(root)
    suffix = SUFFIXES[SENSE_KIND[sense]]
    files = sorted(p for p in root.glob(f"*/*{suffix}") if p.parent.is_dir())
    if not files:
        raise ServantError(f"{root}: no {suffix} files in scene folders; lay out ROOT/<scene>/")
    found = LibraryWindows([], [], [], [])
    for g, path in enumerate(files):
        try:
            samples = read_samples(path, SENSE_KIND[sense], rate)
        except ServantError as error:
            found.skipped.append(str(error))
            continue
        for window in cut_sample_windows(samples, rate):
            found.windows.append(window)
            found.scenes.append(path.parent.name)
            found.groups.append(g)
    return found


def evaluate_library(
    root: str | Path, sense: str, folds: int = 5, seed: int = 0
) -> tuple[SenseScore, list[str]]:
    """Cross-validated score over the library's files (a file's windows stay in one fold), and
    the files skipped."""
    model = new_recogniser(sense, seed)
    found = library_windows(root, sense, model.rate)
    scenes, groups = np.asarray(found.scenes), np.asarray(found.groups)
    per_scene = [len(set(groups[scenes == s])) for s in np.unique(scenes)]
    if len(per_scene) < 2 or min(per_scene) < 2:
        raise ServantError(
            f"{root}: cross-validation needs two scenes with two {sense} files each or more"
        )
    X = model.featurize(found.windows)
    predicted = np.empty(len(scenes), dtype=object)
    splitter = StratifiedGroupKFold(min(folds, min(per_scene)), shuffle=True, random_state=seed)
    for train, test in splitter.split(X, scenes, groups):
        fold_model = new_recogniser(sense, seed).fit(X[train], scenes[train])
        predicted[test] = fold_model.predict(X[test])
    return score(scenes.tolist(), predicted.astype(str).tolist()), found.skipped
