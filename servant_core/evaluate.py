"""Evaluation protocols (DESIGN.md) and the paper's tables.

Audio: `temporal` — the first 60 % of each recording's windows train, the rest test;
`recording` — leave one recording out, train on the rest, pool the predictions;
`source` — leave one source out (a place never heard, through a microphone never heard): the
recordings of a source are the files whose name starts with the same word before its first `-`
(`moodist-cafe.mp3`: `moodist`), or the groups of a `--groups` file;
`fewshot` — the first k windows of each recording train (teach mode: a few presses of the teach
key), the temporal test part tests; `train-test` — one library trains, another tests.
Every protocol can be repeated over random states (`over_seeds`): mean and spread.
Images: a train library and a test library, or one library split by file order per scene.
Fusion: test windows paired with test pictures of the same scene, run through a fusion policy.
"""

from __future__ import annotations

import inspect
import math
from collections import Counter
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.metrics import confusion_matrix

from servant_core.choices import DEFAULT_SHOTS, EVAL_PROTOCOLS, IMAGE_TRAIN_FRACTION
from servant_core.errors import ServantError
from servant_core.events import Decision
from servant_core.fusion import (
    POLICIES,
    FusionConfig,
    FusionNet,
    LearnedFusion,
    scene_line,
)
from servant_core.fusion.learned import SenseOpinions
from servant_core.fusion.learning import (
    DEFAULT_FOLDS,
    picture_opinions,
    train_fusion_net,
    window_opinions,
)
from servant_core.fusion.pipeline import DecisionPipeline, Said
from servant_core.library import (
    Picture,
    SceneLibrary,
    WindowFeatures,
    featurize_recordings,
    iter_recording_windows,
    read_pictures,
    visits_of,
)
from servant_core.recognisers import (
    UNKNOWN,
    AcousticRecogniser,
    Recogniser,
    make_audio_recogniser,
    make_recogniser,
    methods_for,
)
from servant_core.recognisers.background import kept_out
from servant_core.recognisers.base import (
    fit_visits,
    knows_elsewhere,
    open_predict,
    open_probabilities,
)
from servant_core.storage import read_bounded_bytes

PROTOCOLS = EVAL_PROTOCOLS
# For a library taught in the app, 5 s at a time: `temporal` where recordings are long enough to
# split, else `recording` (leave one out: each recording is one sample). The result names which.
TAUGHT = "taught"
TRAIN_FRACTION = 0.6
LOG_EPS = 1e-15


def temporal_split(
    recording: np.ndarray, position: np.ndarray, fraction: float = TRAIN_FRACTION
) -> np.ndarray:
    """Boolean train mask: the first `fraction` of each recording's windows (at least one of
    each side when the recording has two windows or more)."""
    train = np.zeros(len(position), dtype=bool)
    for r in np.unique(recording):
        rows = recording == r
        n = int(rows.sum())
        n_train = min(max(int(math.floor(fraction * n)), 1), max(n - 1, 1))
        train[rows] = position[rows] < n_train
    return train


def file_order_split(
    pictures: Sequence[Picture], fraction: float = IMAGE_TRAIN_FRACTION
) -> np.ndarray:
    """Boolean train mask over pictures: the first `fraction` of each scene's files by name."""
    train = np.zeros(len(pictures), dtype=bool)
    by_scene: dict[str, list[int]] = {}
    for i, picture in enumerate(pictures):
        by_scene.setdefault(picture.scene, []).append(i)
    for indices in by_scene.values():
        indices.sort(key=lambda i: pictures[i].path.name)
        n_train = min(max(int(math.floor(fraction * len(indices))), 1), max(len(indices) - 1, 1))
        train[indices[:n_train]] = True
    return train


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


def featurize_library_audio(
    library: SceneLibrary,
    model: AcousticRecogniser,
    on_error: Callable[[ServantError], None] | None = None,
    on_progress: Callable[[int, int], None] | None = None,
) -> WindowFeatures:
    return featurize_recordings(
        library.recordings,
        model.featurize,
        model.rate,
        model.window_seconds,
        on_error,
        on_progress,
    )


def fewshot_split(
    recording: np.ndarray, position: np.ndarray, shots: int, fraction: float = TRAIN_FRACTION
) -> np.ndarray:
    """Boolean train mask of teach mode's reality: the first `shots` windows of each recording,
    never beyond its temporal train part (so the temporal test part stays unseen)."""
    return temporal_split(recording, position, fraction) & (position < shots)


def source_of(path: Path) -> str:
    """A recording's source: its file name up to the first `-` (`moodist-cafe.mp3`: `moodist`;
    a name without one is a source of its own)."""
    return Path(path).stem.split("-", 1)[0]


# A line a recording: a thousand times the largest library Servant was evaluated on.
MAX_GROUPS_BYTES = 16 << 20


def read_groups(path: Path, root: Path) -> dict[str, str]:
    """A `--groups` file: one recording a line, its path (relative to `root`, or absolute below
    it) and then its group, the line's last word; blank lines and `#` comments are skipped.
    Returns recording path relative to `root` (POSIX) -> group."""
    data = read_bounded_bytes(path, "groups file", MAX_GROUPS_BYTES)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ServantError(f"{path}: cannot read the groups file ({error})") from None
    groups: dict[str, str] = {}
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.rsplit(None, 1)
        if len(parts) != 2:
            raise ServantError(
                f"{path}:{number}: expected a recording's path and then its group, found {line!r}"
            )
        name, group = Path(parts[0]), parts[1]
        if name.is_absolute():
            try:
                name = name.relative_to(root)
            except ValueError:
                raise ServantError(
                    f"{path}:{number}: {name} is not below the scene library {root}"
                ) from None
        groups[name.as_posix()] = group
    return groups


def recording_groups(library: SceneLibrary, groups: Mapping[str, str] | None = None) -> list[str]:
    """The group of each of `library`'s recordings (in its order): from `groups` (recording path
    relative to the library's root -> group), or its source (`source_of`) without one. A
    recording `groups` does not name is an error: guessing its group could leak it into a fold
    that tests its twin."""
    if groups is None:
        return [source_of(r.path) for r in library.recordings]
    names = [r.path.relative_to(library.root).as_posix() for r in library.recordings]
    missing = [name for name in names if name not in groups]
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise ServantError(
            f"the groups file names no group for {', '.join(missing[:3])}{more}; give every "
            "recording of the library a line `PATH GROUP`"
        )
    return [groups[name] for name in names]


@dataclass
class AudioPlan:
    """One scored row: a model per fold fitted on `folds[i]` (train mask over the windows) and
    tested on `tests[i]`; `shots` for a fewshot row; `left_out[i]` names the group fold i
    holds out (source protocol)."""

    protocol: str
    folds: list[np.ndarray]
    tests: list[np.ndarray]
    shots: int | None = None
    left_out: list[str] | None = None


def audio_plans(
    wf: WindowFeatures,
    protocol: str,
    shots: Sequence[int] = DEFAULT_SHOTS,
    groups: Sequence[str] | None = None,
) -> list[AudioPlan]:
    """The folds of `protocol` over `wf`'s windows: `temporal` one fold, `recording` one per
    recording (tested on it alone), `source` one per group of recordings (`groups[i]` is the
    group of `wf.recordings[i]`; default: each recording's source), `fewshot` one row per number
    of shots (each tested on the temporal test part)."""
    temporal = temporal_split(wf.recording, wf.position)
    if protocol == TAUGHT:
        protocol = _taught_protocol(wf, temporal)
    if protocol == "temporal":
        return [AudioPlan(protocol, [temporal], [~temporal])]
    if protocol == "fewshot":
        return [
            AudioPlan(protocol, [fewshot_split(wf.recording, wf.position, k)], [~temporal], k)
            for k in shots
        ]
    if protocol == "source":
        if groups is None:
            groups = [source_of(r.path) for r in wf.recordings]
        if len(groups) != len(wf.recordings):
            raise ValueError("one group per recording of the windows is needed")
        window_group = np.array(groups, dtype=object)[wf.recording]
        left_out = sorted(set(window_group.tolist()))
        tests = [window_group == g for g in left_out]
        return [AudioPlan(protocol, [~t for t in tests], tests, left_out=left_out)]
    rows = [wf.recording != r for r in np.unique(wf.recording)]
    return [AudioPlan(protocol, rows, [~row for row in rows])]


def _taught_protocol(wf: WindowFeatures, temporal: np.ndarray) -> str:
    """What `taught` means for a library: leave one recording out once teach mode's 5 s samples
    (one window each) are in it, so that every sample is tested, not the later part of a longer
    recording alone; `temporal` for a library of longer recordings only."""
    samples = np.bincount(wf.recording, minlength=len(wf.recordings)) == 1
    why_not = _samples_to_leave_out(wf)
    if why_not is None and samples.any():
        return "recording"
    if (~temporal).any():
        return "temporal"
    if why_not is not None:
        raise ServantError(why_not)
    return "recording"


def _samples_to_leave_out(wf: WindowFeatures) -> str | None:
    """Why one sample cannot be left out at a time (teach mode's words), or None: it needs two
    places, each with two samples or more (a place whose only sample is left out cannot be
    recognised)."""
    per_scene = Counter(str(wf.scenes[wf.recording == r][0]) for r in np.unique(wf.recording))
    if len(per_scene) < 2:
        return (
            "nothing to evaluate yet: teach a second place in teach mode (key t), with two "
            "recordings or more"
        )
    single = sorted(scene for scene, n in per_scene.items() if n < 2)
    if single:
        return (
            f"nothing to evaluate yet: record another sample of {', '.join(single)} in teach "
            "mode (key t); each recording here is one window, and one is left out at a time to "
            "test"
        )
    return None


def seeded_params(
    cls_params: dict[str, Any], method: str, sense: str, seed: int | None
) -> dict[str, Any]:
    """`cls_params` with `random_state=seed` when the method takes one (seed None: as given)."""
    if seed is None:
        return cls_params
    init = inspect.signature(methods_for(sense)[method].__init__).parameters
    return {**cls_params, "random_state": seed} if "random_state" in init else cls_params


def _evaluate_folds(
    wf: WindowFeatures,
    plan: AudioPlan,
    make_model: Callable[[], Recogniser],
    names: Sequence[str],
    on_fold: Callable[[], None] | None = None,
) -> dict[str, Any]:
    """Fit one model per fold (train mask), predict its test mask, pool and score;
    `on_fold()` after each fold."""
    preds = Predictions([], [], [])
    tested: list[np.ndarray] = []  # the recording of each test window, in prediction order
    skipped: list[str] = []
    folds: list[dict[str, Any]] = []
    n_train = 0
    visits = visits_of(wf)
    for i, (train, test) in enumerate(zip(plan.folds, plan.tests, strict=True)):
        if plan.left_out is not None:
            folds.append(_fold_summary(wf, train, test, plan.left_out[i], names))
        try:
            model = fit_visits(make_model(), wf.features[train], wf.scenes[train], visits[train])
        except ServantError as error:
            if len(plan.folds) == 1:
                raise
            left_out = np.unique(wf.recording[test])
            skipped.append(f"{', '.join(Path(names[r]).name for r in left_out)}: {error}")
        else:
            preds.extend(model, wf.features[test], wf.scenes[test])
            tested.append(wf.recording[test])
            n_train += int(train.sum())
        if on_fold is not None:
            on_fold()
    result = scores(preds, sorted(set(wf.scenes.tolist())))
    result["per_recording"] = per_recording(preds, np.concatenate(tested), names)
    result.update(n_train=n_train, skipped_folds=skipped)
    if plan.left_out is not None:
        result["folds"] = folds
    return result


def _fold_summary(
    wf: WindowFeatures, train: np.ndarray, test: np.ndarray, left_out: str, names: Sequence[str]
) -> dict[str, Any]:
    """What a fold holds out: its group, its recordings, its windows, and the scenes it tests
    that no training window carries (those windows cannot be named right)."""
    trained = set(wf.scenes[train].tolist())
    return {
        "left_out": left_out,
        "recordings": [names[r] for r in np.unique(wf.recording[test])],
        "n_train": int(train.sum()),
        "n_test": int(test.sum()),
        "unseen_scenes": sorted(set(wf.scenes[test].tolist()) - trained),
    }


def evaluate_windows(
    wf: WindowFeatures,
    names: Sequence[str],
    plans: Sequence[AudioPlan],
    make_model: Callable[[int | None], Recogniser],
    seeds: int = 1,
    on_progress: Callable[[int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """One scored row per plan; `make_model(seed)` gives a fresh model for a random state
    (None: the method's own). Benchmarks score other methods through this same path.
    `on_progress(done, total)` after each model fitted and tested (every fold of every plan,
    for each seed)."""
    rows = []
    total = sum(len(plan.folds) for plan in plans) * max(seeds, 1)
    done = 0

    def fold_done() -> None:
        nonlocal done
        done += 1
        if on_progress is not None:
            on_progress(done, total)

    for plan in plans:

        def run(seed: int | None, plan: AudioPlan = plan) -> dict[str, Any]:
            return _evaluate_folds(wf, plan, lambda: make_model(seed), names, fold_done)

        row = over_seeds(run, seeds)
        row.update(protocol=plan.protocol, sense="audio", n_recordings=len(np.unique(wf.recording)))
        if plan.shots is not None:
            row["shots"] = plan.shots
        rows.append(row)
    return rows


SEED_METRICS = ("accuracy", "balanced_accuracy", "log_loss", "unknown_rate", "elsewhere_rate")


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


def _joined(train: WindowFeatures, test: WindowFeatures) -> WindowFeatures:
    """One set of windows: `test`'s recordings numbered after `train`'s."""
    return WindowFeatures(
        np.concatenate([train.features, test.features]),
        np.concatenate([train.scenes, test.scenes]),
        np.concatenate([train.recording, test.recording + len(train.recordings)]),
        np.concatenate([train.position, test.position]),
        [*train.recordings, *test.recordings],
    )


def evaluate_audio(
    library: SceneLibrary,
    method: str = "paper",
    protocol: str = "temporal",
    params: dict[str, Any] | None = None,
    on_error: Callable[[ServantError], None] | None = None,
    on_progress: Callable[[int, int], None] | None = None,
    *,
    test_library: SceneLibrary | None = None,
    shots: Sequence[int] = DEFAULT_SHOTS,
    seeds: int = 1,
    groups: Mapping[str, str] | None = None,
    on_fold: Callable[[int, int], None] | None = None,
) -> dict[str, Any]:
    """Score `method` on `library`'s windows under `protocol`; with `test_library`, train on all
    of `library` and test on all of `test_library` (protocol `train-test`); `on_progress` follows
    the listening, `on_fold(done, total)` the models fitted and tested. `fewshot` gives one
    row per number of `shots` under `rows`. `source` leaves out one group of recordings at a
    time: `groups` (recording path relative to the root -> group) or each file's source. With
    `seeds` > 1 every figure is a mean over random states 0..seeds-1 (see `over_seeds`)."""
    if protocol not in (*PROTOCOLS, TAUGHT):
        raise ServantError(f"unknown protocol {protocol!r}; choose {', '.join(PROTOCOLS)}")
    if protocol == "fewshot" and (not shots or min(shots) < 1):
        raise ServantError("--shots needs whole numbers of windows, each at least 1 (e.g. 1,3,10)")
    params = params or {}
    recording_group = recording_groups(library, groups) if protocol == "source" else None
    probe = make_audio_recogniser(method, **params)
    wf = featurize_library_audio(library, probe, on_error, on_progress)
    names = [str(r.path.relative_to(library.root)) for r in wf.recordings]
    if test_library is not None:
        test_wf = featurize_library_audio(test_library, probe, on_error, on_progress)
        names += [str(r.path.relative_to(test_library.root)) for r in test_wf.recordings]
        train = np.arange(len(wf.scenes) + len(test_wf.scenes)) < len(wf.scenes)
        wf = _joined(wf, test_wf)
        plans = [AudioPlan("train-test", [train], [~train])]
    else:
        plans = audio_plans(wf, protocol, shots, recording_group)
    rows = evaluate_windows(
        wf,
        names,
        plans,
        lambda seed: kept_out(
            make_audio_recogniser(method, **seeded_params(params, method, "audio", seed)),
            wf.recordings,
        ),
        seeds,
        on_fold,
    )
    for row in rows:
        row["method"] = method
    if protocol != "fewshot" or test_library is not None:
        return rows[0]
    return {"method": method, "protocol": protocol, "sense": "audio", "seeds": seeds, "rows": rows}


def _pictures_and_features(
    model: Recogniser,
    pictures: Sequence[Picture],
    on_error: Callable[[ServantError], None] | None,
    on_progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, list[Picture]]:
    images, kept = read_pictures(pictures, on_error, on_progress)
    if not kept:
        raise ServantError("no readable picture")
    return model.featurize(images), kept


def evaluate_image(
    train_library: SceneLibrary,
    test_library: SceneLibrary | None = None,
    method: str = "paper",
    split: float = IMAGE_TRAIN_FRACTION,
    params: dict[str, Any] | None = None,
    on_error: Callable[[ServantError], None] | None = None,
    seeds: int = 1,
) -> dict[str, Any]:
    """Train on `train_library`'s pictures and test on `test_library`'s; with no test library,
    split each scene's pictures by file order (the first `split` train). With `seeds` > 1 the
    figures are means over random states 0..seeds-1 (see `over_seeds`); pictures are featurized
    once (featurizing depends on the parameters only)."""
    params = params or {}
    model = make_recogniser("image", method, **params)
    if test_library is None:
        X, kept = _pictures_and_features(model, train_library.pictures, on_error)
        train = file_order_split(kept, split)
        X_train, y_train = X[train], [p.scene for p, t in zip(kept, train, strict=True) if t]
        X_test, y_test = X[~train], [p.scene for p, t in zip(kept, train, strict=True) if not t]
        protocol = f"file-order-{split:g}"
        if not y_test:
            raise ServantError(
                f"{train_library.root}: nothing to evaluate: the file-order split keeps every "
                "picture for training (a scene needs two pictures or more); take more pictures "
                "or give a test library (--test)"
            )
    else:
        X_train, kept_train = _pictures_and_features(model, train_library.pictures, on_error)
        X_test, kept_test = _pictures_and_features(model, test_library.pictures, on_error)
        y_train = [p.scene for p in kept_train]
        y_test = [p.scene for p in kept_test]
        protocol = "train-test"

    def run(seed: int | None) -> dict[str, Any]:
        fitted = make_recogniser("image", method, **seeded_params(params, method, "image", seed))
        fitted.fit(X_train, y_train)
        preds = Predictions([], [], [])
        preds.extend(fitted, X_test, y_test)
        return scores(preds, sorted(set(y_train) | set(y_test)))

    result = over_seeds(run, seeds)
    result.update(method=method, protocol=protocol, sense="image", n_train=len(y_train))
    return result


def _paired_scenes(
    library: SceneLibrary, test_library: SceneLibrary | None, needs: str
) -> list[str]:
    """The sorted scenes with both recordings and pictures in `library` (and in `test_library`,
    if given); at least two, or a ServantError that says what `needs` them."""
    paired = sorted({r.scene for r in library.recordings} & {p.scene for p in library.pictures})
    if test_library is not None:
        paired = [
            s
            for s in paired
            if any(r.scene == s for r in test_library.recordings)
            and any(p.scene == s for p in test_library.pictures)
        ]
    if len(paired) < 2:
        raise ServantError(
            f"{library.root}: {needs} at least two scenes with both recordings and pictures"
        )
    return paired


@dataclass
class PairedFit:
    """Both recognisers fitted on one library, and what they were fitted on."""

    audio: AcousticRecogniser
    windows: WindowFeatures
    window_train: np.ndarray  # which of `windows` trained `audio`
    visual: Recogniser
    picture_features: np.ndarray  # rows of `pictures`
    pictures: list[Picture]  # the readable pictures
    picture_train: np.ndarray  # which of `pictures` trained `visual`


def fit_paired(
    library: SceneLibrary,
    acoustic_method: str,
    visual_method: str,
    on_error: Callable[[ServantError], None] | None,
    train_on_all: bool = False,
    on_progress: Callable[[str], Callable[[int, int], None]] | None = None,
) -> PairedFit:
    """The acoustic recogniser trained on the temporal split of the library's windows, the visual
    one on the file-order split of its pictures; on all of both with `train_on_all` (when the
    test items come from another library). `on_progress(step)` gives the callback of each step
    ("listening to recordings", "reading pictures")."""
    audio = make_audio_recogniser(acoustic_method)
    heard = on_progress("listening to recordings") if on_progress else None
    wf = featurize_library_audio(library, audio, on_error, heard)
    train = (
        np.ones(len(wf.scenes), bool) if train_on_all else temporal_split(wf.recording, wf.position)
    )
    fit_visits(audio, wf.features[train], wf.scenes[train], visits_of(wf)[train])
    visual = make_recogniser("image", visual_method)
    seen = on_progress("reading pictures") if on_progress else None
    X, kept = _pictures_and_features(visual, library.pictures, on_error, seen)
    p_train = (
        np.ones(len(kept), bool) if train_on_all else file_order_split(kept, IMAGE_TRAIN_FRACTION)
    )
    visual.fit(X[p_train], [p.scene for p, t in zip(kept, p_train, strict=True) if t])
    return PairedFit(audio, wf, train, visual, X, kept, p_train)


SENSES = ("audio", "image")


def run_encounter(
    policy: Any,
    config: FusionConfig,
    acoustic: Said | None,
    visual: Sequence[Said],
    open_roles: Collection[str] = (),
) -> Decision:
    """One scene encounter through a fresh decision pipeline around `policy`
    (`DecisionPipeline.encounter`): what the live engine would decide of these opinions."""
    return DecisionPipeline(policy).encounter(config, acoustic, visual, open_roles)


def run_fusion(
    policy_name: str,
    config: FusionConfig,
    acoustic: tuple[str, float],
    visual: Sequence[tuple[str, float]],
) -> Any:
    """One scene encounter through a rule policy (see `run_encounter`). Returns the Decision."""
    if acoustic[0] == UNKNOWN:
        # An unknown place opens no window in any policy: nothing to confirm, no decision.
        return Decision(0.0, None, 0.0, scene_line(None))
    return run_encounter(
        POLICIES[policy_name](config),
        config,
        (*acoustic, None),
        [(*v, None) for v in visual],
    )


def said_of(model: Recogniser, X: np.ndarray) -> list[Said]:
    """Each row's opinion: scene, confidence and probability per scene (and not somewhere
    else, where the recogniser knows somewhere else)."""
    scenes, confidences = open_predict(model, X), model.confidence(X)
    proba = open_probabilities(model, X)
    return [
        (
            str(scenes[i]),
            float(confidences[i]),
            dict(zip(model.scenes_, map(float, proba[i]), strict=True)),
        )
        for i in range(len(scenes))
    ]


def fusion_opinions(fitted: PairedFit, folds: int = DEFAULT_FOLDS) -> dict[str, SenseOpinions]:
    """Each sense's held-out opinions of its own training part (see
    `servant_core.fusion.learning`): what the learned fusion is trained on."""
    wf, train = fitted.windows, fitted.window_train
    windows = WindowFeatures(
        wf.features[train], wf.scenes[train], wf.recording[train], wf.position[train], wf.recordings
    )
    p_train = np.flatnonzero(fitted.picture_train)
    return {
        "audio": window_opinions(fitted.audio, windows, folds),
        "image": picture_opinions(
            fitted.visual,
            fitted.picture_features[p_train],
            [fitted.pictures[i] for i in p_train],
            folds,
        ),
    }


FUSION_METRICS = ("decision_rate", "precision", "accuracy")


@dataclass
class FusionSetup:
    """What a fusion evaluation runs encounters from: each test window's acoustic opinion and
    its true scene, each scene's test pictures' opinions, and (for the learned fusion) each
    sense's held-out opinions of the training parts."""

    scenes: list[str]
    truth: np.ndarray
    acoustic: list[Said]
    pictures: dict[str, list[Said]]
    opinions: dict[str, SenseOpinions] | None = None
    open_roles: frozenset[str] = frozenset()  # the roles whose recogniser knows elsewhere


def fusion_setup(
    library: SceneLibrary,
    acoustic_method: str,
    visual_method: str,
    on_error: Callable[[ServantError], None] | None = None,
    folds: int | None = DEFAULT_FOLDS,
) -> FusionSetup:
    """Fit both recognisers on the training parts of `library`'s paired scenes and judge the
    test parts; with `folds`, also the held-out opinions the learned fusion trains on."""
    paired = _paired_scenes(library, None, "fusion needs")
    fitted = fit_paired(library.restricted(paired), acoustic_method, visual_method, on_error)
    wf, train = fitted.windows, fitted.window_train
    test_pics = [i for i, t in enumerate(fitted.picture_train) if not t]
    visual = said_of(fitted.visual, fitted.picture_features[test_pics])
    pictures: dict[str, list[Said]] = {}
    for k, i in enumerate(test_pics):
        pictures.setdefault(fitted.pictures[i].scene, []).append(visual[k])
    return FusionSetup(
        paired,
        wf.scenes[~train],
        said_of(fitted.audio, wf.features[~train]),
        pictures,
        fusion_opinions(fitted, folds) if folds else None,
        frozenset(
            role
            for role, recogniser in (("acoustic", fitted.audio), ("visual", fitted.visual))
            if knows_elsewhere(recogniser)
        ),
    )


def score_fusion(
    setup: FusionSetup,
    make_policy: Callable[[], Any],
    config: FusionConfig,
    drop_sense: str | None = None,
) -> dict[str, Any]:
    """Each test window meets its scene's test pictures, in turn, through a fresh policy;
    `drop_sense` withholds that sense. Decision rate, precision, accuracy, and which senses the
    decisions leaned on."""
    decided = right = 0
    leaned: Counter[str] = Counter()
    cursor = dict.fromkeys(setup.pictures, 0)
    for i, scene in enumerate(setup.truth):
        # a scene whose pictures all went to training (one picture) shows its windows none
        pics = setup.pictures.get(scene, [])
        start = cursor.get(scene, 0)
        shown = [pics[(start + j) % len(pics)] for j in range(len(pics))]
        if pics:
            cursor[scene] = (start + config.pictures_needed) % len(pics)
        heard = None if drop_sense == "audio" else setup.acoustic[i]
        decision = run_encounter(
            make_policy(), config, heard, [] if drop_sense == "image" else shown, setup.open_roles
        )
        if decision.scene is not None:
            decided += 1
            right += decision.scene == scene
            leaned.update(["+".join(decision.leaned_on) or "-"])
    n = len(setup.truth)
    return {
        "decision_rate": decided / n if n else 0.0,
        "precision": right / decided if decided else 0.0,
        "accuracy": right / n if n else 0.0,
        "leaned_on": dict(leaned.most_common()),
    }


def score_learned(
    setup: FusionSetup, config: FusionConfig, drop_sense: str | None = None, seeds: int = 1
) -> dict[str, Any]:
    """The learned fusion over net random states 0..seeds-1: each seed's net is trained on the
    setup's held-out opinions; one seed's figures, or their mean, spread and `per_seed`."""
    if setup.opinions is None:
        raise ValueError("the learned fusion needs a setup made with folds")
    runs = []
    for seed in range(seeds):
        net, reason = train_fusion_net(setup.opinions, random_state=seed)

        def make_policy(net: FusionNet | None = net) -> LearnedFusion:
            return LearnedFusion(config, net)

        row = score_fusion(setup, make_policy, config, drop_sense)
        row.update(
            random_state=seed,
            threshold=net.threshold_ if net is not None else None,
            fallback=reason,
        )
        runs.append(row)
    result = dict(runs[0])
    result["n_train"] = {sense: len(o.truth) for sense, o in setup.opinions.items()}
    if seeds > 1:
        result.pop("random_state")
        result["seeds"] = seeds
        result["per_seed"] = runs
        averaged(result, runs, FUSION_METRICS)
    return result


def evaluate_fusion(
    library: SceneLibrary,
    acoustic_method: str = "paper",
    visual_method: str = "paper",
    policy: str = "sequential",
    config: FusionConfig | None = None,
    on_error: Callable[[ServantError], None] | None = None,
    *,
    drop_sense: str | None = None,
    seeds: int = 1,
    folds: int = DEFAULT_FOLDS,
) -> dict[str, Any]:
    """Each test window (temporal split) of a scene that also has pictures is paired with that
    scene's test pictures (file-order split), in turn; the policy decides or not. Reports how
    often it decides and, when it names a scene, how often it is right.

    `learned`: the net is trained on each sense's held-out opinions of the training parts
    (`fusion_opinions`), over net random states 0..seeds-1 (mean, spread, per seed).
    `drop_sense` ("audio" or "image") withholds that sense at test time."""
    if policy not in POLICIES:
        raise ServantError(
            f"unknown fusion policy {policy!r}; choose {', '.join(sorted(POLICIES))}"
        )
    if drop_sense is not None and drop_sense not in SENSES:
        raise ServantError(f"no sense named {drop_sense!r} to drop; choose {', '.join(SENSES)}")
    if seeds < 1:
        raise ServantError(f"--seeds must be at least 1, not {seeds}")
    config = config or FusionConfig()
    learned = policy == "learned"
    setup = fusion_setup(
        library, acoustic_method, visual_method, on_error, folds if learned else None
    )
    result: dict[str, Any] = {
        "method": f"{acoustic_method}+{visual_method}",
        "acoustic_method": acoustic_method,
        "visual_method": visual_method,
        "policy": policy,
        "protocol": "temporal+file-order",
        "scenes": setup.scenes,
        "n_test": len(setup.truth),
        "drop_sense": drop_sense,
    }
    if learned:
        result.update(score_learned(setup, config, drop_sense, seeds))
    else:
        result.update(score_fusion(setup, lambda: POLICIES[policy](config), config, drop_sense))
    return result


def _first_test_items(
    library: SceneLibrary,
    test_library: SceneLibrary | None,
    scenes: Sequence[str],
    rate: int,
    seconds: float,
    on_error: Callable[[ServantError], None] | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, tuple[Picture, np.ndarray]]]:
    """One test window and one test picture (with its pixels) per scene. Without a test library
    they are held out of `library`: a window after the temporal split point, a picture after the
    file-order split. A file that cannot be read goes to `on_error` (which may raise) and the
    next one is taken."""
    windows: dict[str, np.ndarray] = {}
    pictures: dict[str, tuple[Picture, np.ndarray]] = {}
    source = test_library if test_library is not None else library
    for scene in scenes:
        recs = [r for r in source.recordings if r.scene == scene]
        for _, _, w in iter_recording_windows(recs, rate, seconds, on_error):
            index = (
                0
                if test_library is not None
                else min(max(int(math.floor(TRAIN_FRACTION * len(w))), 1), len(w) - 1)
            )
            windows[scene] = w[index : index + 1]
            break  # the first readable recording
        pics = sorted((p for p in source.pictures if p.scene == scene), key=lambda p: p.path.name)
        index = (
            0
            if test_library is not None
            else min(max(int(math.floor(IMAGE_TRAIN_FRACTION * len(pics))), 1), len(pics) - 1)
        )
        for picture in pics[index:]:
            images, kept = read_pictures([picture], on_error)
            if kept:
                pictures[scene] = (picture, images[0])
                break
        if scene not in windows or scene not in pictures:
            raise ServantError(
                f"{source.root}: {scene}: no readable recording or picture left to test on"
            )
    return windows, pictures


def paper_tables(
    library: SceneLibrary,
    test_library: SceneLibrary | None = None,
    acoustic_method: str = "paper",
    visual_method: str = "paper",
    config: FusionConfig | None = None,
    on_error: Callable[[ServantError], None] | None = None,
    on_progress: Callable[[str], Callable[[int, int], None]] | None = None,
) -> dict[str, Any]:
    """The paper's Table I (terminal line per picture × recording) and Table II (average
    confidence per cell, 0.000 where no scene), for every scene with recordings and pictures;
    `on_progress` as `fit_paired`'s."""
    config = config or FusionConfig()
    paired = _paired_scenes(library, test_library, "the tables need")
    library = library.restricted(paired)
    fitted = fit_paired(
        library,
        acoustic_method,
        visual_method,
        on_error,
        train_on_all=test_library is not None,
        on_progress=on_progress,
    )
    audio, visual = fitted.audio, fitted.visual

    windows, pictures = _first_test_items(
        library,
        test_library,
        paired,
        audio.rate,
        audio.window_seconds,
        on_error,
    )
    cells: dict[str, dict[str, dict[str, Any]]] = {}
    for picture_scene in paired:
        Xv = visual.featurize([pictures[picture_scene][1]])
        v = (str(visual.predict(Xv)[0]), float(visual.confidence(Xv)[0]))
        cells[picture_scene] = {}
        for recording_scene in paired:
            Xa = audio.featurize(windows[recording_scene])
            a = (str(audio.predict(Xa)[0]), float(audio.confidence(Xa)[0]))
            decision = run_fusion("sequential", config, a, [v])
            cells[picture_scene][recording_scene] = {
                "line": decision.line,
                "confidence": decision.confidence,
                "acoustic": {"scene": a[0], "confidence": a[1]},
                "visual": {"scene": v[0], "confidence": v[1]},
            }
    return {
        "scenes": paired,
        "acoustic_method": acoustic_method,
        "visual_method": visual_method,
        "confidence_units": {"acoustic": audio.confidence_unit, "visual": visual.confidence_unit},
        "pictures": {s: str(p.path) for s, (p, _) in pictures.items()},
        "cells": cells,
    }


def format_tables(tables: dict[str, Any]) -> str:
    """Plain-text Table I and Table II: rows are pictures, columns are recordings."""
    scenes = tables["scenes"]
    cells = tables["cells"]
    head = ["picture \\ recording", *scenes]

    def grid(title: str, value: Callable[[dict[str, Any]], str]) -> list[str]:
        rows = [[f"{s} picture", *(value(cells[s][r]) for r in scenes)] for s in scenes]
        widths = [max(len(str(x)) for x in col) for col in zip(head, *rows, strict=True)]
        fmt = "  ".join(f"{{:<{w}}}" for w in widths)
        return [title, fmt.format(*head), *(fmt.format(*row) for row in rows)]

    lines = [_tables_header(tables), ""]
    lines += grid("Table I: terminal output", lambda c: c["line"])
    lines.append("")
    units = list(tables.get("confidence_units", {}).values())
    unit = "%" if set(units) == {"%"} else f"mean of {' and '.join(map(str, units))}"
    title = f"Table II: average confidence ({unit})" if units else "Table II: average confidence"
    lines += grid(title, lambda c: f"{c['confidence']:.3f}")
    return "\n".join(lines)


def _tables_header(tables: dict[str, Any]) -> str:
    """What the tables are of: the methods, and the unit of their confidences."""
    audio, image = tables["acoustic_method"], tables["visual_method"]
    units = tables.get("confidence_units", {})
    if (audio, image) == ("paper", "paper"):
        return (
            "The paper's method (its Tables I and II): sound by K-Means on FFT windows, pictures "
            "by dominant colours, decided by its sequential 30 s / 20 s rule. Confidences are "
            "the mean of its eq. 1 (sound: 100 - distance / 10000) and eq. 2 (pictures: 100 - "
            "distance), not percentages: far below zero is usual."
        )
    said = ", ".join(f"{sense} {unit}" for sense, unit in units.items()) or "not said"
    return (
        f"Tables I and II as the paper's, with sound by `{audio}` and pictures by `{image}`, "
        f"decided by the paper's sequential rule; confidences: {said}."
    )
