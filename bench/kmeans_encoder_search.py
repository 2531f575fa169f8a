"""How `kmeans-encoder`'s defaults are chosen: scored by cross-validation grouped by recording
inside the training data only; the dev protocols' test parts are never looked at.

The training data is the temporal protocol's training part: the first 60 % of every recording's
windows (what `servant eval audio --protocol temporal` and `--protocol fewshot` train on; their
test part, the last 40 %, stays unseen here). Inside it, three criteria (balanced accuracy):
- grouped: GroupKFold over recordings (5 folds): whole recordings held out, the rest train
  (a place heard through another microphone);
- teach k=1 and k=3: the first k windows of every recording train, the last 40 % of each
  recording's training part tests (teach mode, one level down).
The score is the mean of the three. Coordinate search from the current defaults: each parameter
in turn takes the value of `GRID` with the best score (a tie keeps the earlier, cheaper value),
the others held at their best so far; one pass.

    OMP_NUM_THREADS=1 python bench/kmeans_encoder_search.py [--data ../shared/data/audio/dev]
        [--cache /tmp/servant-search]   # featurized windows kept between runs
        [--try '{"noise_copies": 2}' ...]   # score the defaults and these changes, no search
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.model_selection import GroupKFold

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import shared_data  # noqa: E402

from servant_core.evaluate import (  # noqa: E402
    AudioPlan,
    evaluate_windows,
    fewshot_split,
    temporal_split,
)
from servant_core.library import SceneLibrary, WindowFeatures, featurize_recordings  # noqa: E402
from servant_core.recognisers.kmeans_encoder import KMeansEncoderAcousticRecogniser  # noqa: E402

# In the order searched; the first value of each is not privileged, the defaults start.
GRID: dict[str, list[Any]] = {
    "C": [0.1, 0.5, 2.0],
    "augment": [2, 4, 6],
    "eq_strength": [0.2, 0.45, 0.8],
    "crops": [0, 4, 8],
    "crop_fraction": [0.25, 0.5],
    "n_codewords": [32, 64, 128],
    "n_mels": [40, 64],
    "encoding_weight": [1.0, 0.5, 0.3, 0.15, 0.1, 0.05],
    "modulation_groups": [0, 4, 8, 16],
    "modulation_weight": [1.0, 0.5, 0.3],
}
FEATURE_PARAMS = ("n_mels", "frame_seconds", "fmin", "fmax", "rate")
FOLDS = 5
TEACH_SHOTS = (1, 3)


def inner_plans(wf: WindowFeatures) -> list[AudioPlan]:
    """The criteria's folds, all inside the temporal training part (`wf` holds only it)."""
    everything = np.arange(len(wf.scenes))
    folds = GroupKFold(FOLDS).split(everything, wf.scenes, wf.recording)
    trains = [np.isin(everything, train) for train, _ in folds]
    plans = [AudioPlan("grouped", trains, [~t for t in trains])]
    inner_test = ~temporal_split(wf.recording, wf.position)
    for k in TEACH_SHOTS:
        plans.append(
            AudioPlan("teach", [fewshot_split(wf.recording, wf.position, k)], [inner_test], k)
        )
    return plans


def training_part(library: SceneLibrary, params: dict[str, Any], cache: Path | None):
    """The featurized windows of the temporal training part, for these feature parameters."""
    probe = KMeansEncoderAcousticRecogniser(**params)
    key = {name: getattr(probe, name) for name in FEATURE_PARAMS}
    path = None
    if cache is not None:
        digest = hashlib.sha1(json.dumps([str(library.root), key]).encode()).hexdigest()[:12]
        path = cache / f"kmeans-encoder-{digest}.npz"
    if path is not None and path.exists():
        z = np.load(path)
        wf = WindowFeatures(
            z["features"], z["scenes"], z["recording"], z["position"], list(library.recordings)
        )
    else:
        wf = featurize_recordings(library.recordings, probe.featurize, probe.rate, 5.0)
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savez(
                path,
                features=wf.features,
                scenes=wf.scenes,
                recording=wf.recording,
                position=wf.position,
            )
    train = temporal_split(wf.recording, wf.position)
    return WindowFeatures(
        wf.features[train], wf.scenes[train], wf.recording[train], wf.position[train], wf.recordings
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data() / "audio" / "dev")
    parser.add_argument("--cache", type=Path, default=None)
    parser.add_argument(
        "--try",
        dest="tries",
        action="append",
        type=json.loads,
        default=[],
        help="JSON parameters to score against the defaults instead of searching (repeatable)",
    )
    args = parser.parse_args()
    library = SceneLibrary.scan(args.data)
    names = [str(r.path.relative_to(library.root)) for r in library.recordings]
    defaults = KMeansEncoderAcousticRecogniser().params()
    best = {name: defaults[name] for name in GRID}
    scored: dict[str, float] = {}

    def score(params: dict[str, Any]) -> float:
        key = json.dumps(params, sort_keys=True)
        if key in scored:
            return scored[key]
        start = time.perf_counter()
        wf = training_part(library, params, args.cache)
        rows = evaluate_windows(
            wf,
            names,
            inner_plans(wf),
            lambda seed: KMeansEncoderAcousticRecogniser(**params, random_state=0),
        )
        figures = [r["balanced_accuracy"] for r in rows]
        scored[key] = float(np.mean(figures))
        shown = " ".join(f"{f:.3f}" for f in figures)
        print(
            f"{json.dumps(params):<110} {shown}  mean {scored[key]:.3f}"
            f"  {time.perf_counter() - start:.0f} s",
            flush=True,
        )
        return scored[key]

    print(f"{'params':<110} grouped teach1 teach3")
    if args.tries:
        for change in [{}, *args.tries]:
            score({**best, **change})
        return
    for name, values in GRID.items():
        results = [(score({**best, name: value}), value) for value in values]
        top = max(r[0] for r in results)
        best[name] = next(value for s, value in results if s == top)
    print(f"chosen: {json.dumps(best)} (mean {score(best):.3f})")


if __name__ == "__main__":
    main()
