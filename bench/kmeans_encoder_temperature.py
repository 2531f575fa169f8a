"""How `kmeans-encoder`'s temperature is chosen: the log loss of folds inside the training data.

The same training data and folds as `kmeans_encoder_search.py` (the first 60 % of every
recording's windows; the dev protocols' test parts are never read): GroupKFold over recordings
(5 folds, whole recordings held out; a window is scored only if its scene is still taught by
other recordings, as in `--protocol recording --scenes`, since no temperature gives a scene the
model was never taught any probability), teach k=1 and k=3, and inner temporal (the first 60 % of
each recording's training part trains, the rest tests). Each fold's model is fitted once; its
logits on the held-out windows are divided by every temperature of `TEMPERATURES`, the
probabilities pooled over the folds and the random states, and the log loss (the mean −log of
the probability given to the truth, as `servant eval` reports it) printed per criterion. Grouped
alone keeps falling to the end of the grid (a recording never heard is best met with nearly
even odds), while teach k=1 and k=3 rise past T 1.25 (windows of recordings it has heard are
named right, and softer odds cost them): the temperature chosen is the one with the lowest mean
log loss over grouped, teach k=1 and teach k=3, the three criteria of the parameter search;
inner temporal is printed, not chosen on. A temperature never changes a decision:
balanced accuracy is printed once.

    OMP_NUM_THREADS=1 python bench/kmeans_encoder_temperature.py [--seeds 3]
        [--data ../shared/data/audio/dev] [--cache /tmp/servant-search]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import shared_data  # noqa: E402
from kmeans_encoder_search import inner_plans, training_part  # noqa: E402

from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.evaluate import LOG_EPS, AudioPlan, temporal_split  # noqa: E402
from servant_core.library import SceneLibrary, WindowFeatures  # noqa: E402
from servant_core.recognisers.kmeans_encoder import KMeansEncoderAcousticRecogniser  # noqa: E402

TEMPERATURES = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 2.5, 3.0, 4.0, 5.0)


def criteria(wf: WindowFeatures) -> list[tuple[str, AudioPlan]]:
    """The search's three criteria, and inner temporal (every window of the training part's
    first 60 % trains)."""
    grouped, teach1, teach3 = inner_plans(wf)
    inner_train = temporal_split(wf.recording, wf.position)
    temporal = AudioPlan("temporal", [inner_train], [~inner_train])
    return [("grouped", grouped), ("teach1", teach1), ("teach3", teach3), ("temporal", temporal)]


def held_out_logits(
    wf: WindowFeatures, plan: AudioPlan, seed: int
) -> tuple[list[np.ndarray], list[int], list[str]]:
    """The logits of each fold's held-out windows whose scene the fold's model knows (fitted at
    temperature 1), the column of each window's true scene, its scene."""
    logits, truth_column, truth = [], [], []
    for train, test in zip(plan.folds, plan.tests, strict=True):
        model = KMeansEncoderAcousticRecogniser(temperature=1.0, random_state=seed)
        model.fit(wf.features[train], wf.scenes[train])
        D = model.descriptors(wf.features[test])
        scores = D @ model.coef_.T + model.intercept_
        column = {s: j for j, s in enumerate(model.scenes_)}
        for row, scene in zip(scores, wf.scenes[test], strict=True):
            if str(scene) not in column:  # its only recording held out: no temperature helps
                continue
            logits.append(row)
            truth_column.append(column[str(scene)])
            truth.append(str(scene))
    return logits, truth_column, truth


def log_loss(logits: list[np.ndarray], truth_column: list[int], temperature: float) -> float:
    p = []
    for row, j in zip(logits, truth_column, strict=True):
        z = row / temperature
        z = z - z.max()
        proba = np.exp(z) / np.exp(z).sum()
        p.append(proba[j])
    return float(-np.mean(np.log(np.clip(p, LOG_EPS, 1.0))))


def balanced_accuracy(logits: list[np.ndarray], truth_column: list[int], truth: list[str]) -> float:
    right = np.array([np.argmax(r) == j for r, j in zip(logits, truth_column, strict=True)])
    scenes = np.array(truth)
    return float(np.mean([right[scenes == s].mean() for s in np.unique(scenes)]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data() / "audio" / "dev")
    parser.add_argument("--cache", type=Path, default=None)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args()
    library = SceneLibrary.scan(args.data)
    wf = training_part(library, KMeansEncoderAcousticRecogniser().params(), args.cache)
    print(f"{'criterion':<10} {'bal.acc':>7}  " + " ".join(f"T={t:<5g}" for t in TEMPERATURES))
    chosen = {}
    losses_of: dict[str, list[float]] = {}
    for name, plan in criteria(wf):
        logits: list[np.ndarray] = []
        columns: list[int] = []
        truth: list[str] = []
        for seed in range(args.seeds):
            fold_logits, fold_columns, fold_truth = held_out_logits(wf, plan, seed)
            logits += fold_logits
            columns += fold_columns
            truth += fold_truth
        losses = [log_loss(logits, columns, t) for t in TEMPERATURES]
        chosen[name] = TEMPERATURES[int(np.argmin(losses))]
        losses_of[name] = losses
        shown = " ".join(f"{loss:<7.3f}" for loss in losses)
        print(f"{name:<10} {balanced_accuracy(logits, columns, truth):7.3f}  {shown}", flush=True)
    mean = np.mean([losses_of[name] for name in ("grouped", "teach1", "teach3")], axis=0)
    print(f"{'mean of 3':<10} {'':>7}  " + " ".join(f"{loss:<7.3f}" for loss in mean))
    print(f"lowest log loss at T = {chosen}; chosen: {TEMPERATURES[int(np.argmin(mean))]:g}")


if __name__ == "__main__":
    with library_noise_silenced():  # mpg123 warns of one real MP3 on descriptor 2
        main()
