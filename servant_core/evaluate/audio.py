"""Scoring a sound recogniser: its windows featurized once, a model fitted per fold of a plan.

`evaluate_audio` is `servant eval audio`; `evaluate_windows` scores any method over the folds of
`audio_plans`, the path the benchmarks' peers go through too.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from servant_core.choices import DEFAULT_SHOTS
from servant_core.errors import ServantError
from servant_core.evaluate.metrics import (
    Predictions,
    over_seeds,
    per_recording,
    scores,
    seeded_params,
)
from servant_core.evaluate.splits import (
    PROTOCOLS,
    TAUGHT,
    AudioPlan,
    audio_plans,
    recording_groups,
)
from servant_core.library import (
    SceneLibrary,
    WindowFeatures,
    featurize_recordings,
    visits_of,
)
from servant_core.recognisers import AcousticRecogniser, Recogniser, make_audio_recogniser
from servant_core.recognisers.background import kept_out
from servant_core.recognisers.base import fit_visits


def featurize_library_audio(
    library: SceneLibrary,
    model: AcousticRecogniser,
    on_error: Callable[[ServantError], None] | None = None,
    on_progress: Callable[[int, int], None] | None = None,
) -> WindowFeatures:
    """Every window of `library`'s recordings, featurized as `model` hears them."""
    return featurize_recordings(
        library.recordings,
        model.featurize,
        model.rate,
        model.window_seconds,
        on_error,
        on_progress,
    )


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
