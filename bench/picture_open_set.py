"""Can the pictures know somewhere else? A picture open set from the few pictures a wearer teaches.

The sound knows somewhere else (a background of places it may ship, `<elsewhere>`, and the
nearest taught window); the pictures do not, and are shown as "× average" beside it
(`fusion/elsewhere.py`). This bench asks whether they could: for each library size and draw,
`--pictures` pictures of each taught picture scene are taught to `--method` (`fisher-bovw`
unless told; `effnet`: an ImageNet network's embedding under the sound's head) (as teach mode
and `bench/wearer_day.py` teach them), then it scores other pictures of the taught scenes (the
same kind of place: another café, as the walk shows them) against pictures of scenes not taught.

Each score is how much a picture looks like a taught place (higher: taught); its ROC AUC says
how well it tells "a taught kind" from "somewhere else" whatever the threshold (0.5: not at all):

- nearest taught picture: the cosine to the nearest taught picture of the place the head names,
  in the head's space (what `birdnet`'s `accept_cosine` does for the sound);
- place centre: minus the distance to the mean of that place's taught pictures (the idea of the
  picture's `SceneCentroids`);
- head's top share: the head's largest probability among the taught places;
- with a background: half of the untaught scenes' pictures (`--background` of each) taught as an
  `<elsewhere>` class beside the taught places, 1 − its probability, scored on the other half
  (a background of real scene pictures, as a shipped one would be, had Servant one it may
  redistribute);
- a plain peer: the cosine to the nearest taught picture by square-rooted HSV histogram alone.

Also: the share of untaught pictures the recogniser's own open set (`SceneCentroids`) calls
unknown, and of taught-kind pictures.

    OMP_NUM_THREADS=1 python bench/picture_open_set.py [--sizes 2,3,5] [--draws 6]
        [--pictures 6] [--background 100] [--method fisher-bovw]
"""

from __future__ import annotations

import argparse
import sys
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.metrics import roc_auc_score

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import shared_data  # noqa: E402
from servant_core.features.descriptors import hsv_histogram, square_thumbnail  # noqa: E402
from servant_core.library import read_picture  # noqa: E402
from servant_core.recognisers import UNKNOWN, make_recogniser  # noqa: E402
from servant_core.recognisers.background import ELSEWHERE  # noqa: E402
from servant_core.recognisers.base import open_predict  # noqa: E402

TESTED = 40  # pictures a scene is tested on


def unit(rows: np.ndarray) -> np.ndarray:
    return rows / (np.linalg.norm(rows, axis=1, keepdims=True) + 1e-12)


def nearest_cosine(rows: np.ndarray, named: np.ndarray, taught: np.ndarray, y: np.ndarray) -> Any:
    """Each row's cosine to the nearest `taught` row of the place it is `named`."""
    rows, taught = unit(rows), unit(taught)
    return np.array([np.max(r @ taught[y == n].T) for r, n in zip(rows, named, strict=True)])


def one_draw(X: np.ndarray, hsv: np.ndarray, scenes: np.ndarray, size: int, args: Any, rng: Any):
    kinds = sorted(set(scenes))
    order = [str(k) for k in rng.permutation(kinds)]
    taught, rest = order[:size], order[size:]
    unseen = rest[len(rest) // 2 :]  # the rest of the untaught scenes are the background
    train, same_kind, elsewhere, far_half, back = [], [], [], [], []
    for kind in kinds:
        rows = rng.permutation(np.flatnonzero(scenes == kind))
        if kind in taught:
            train += list(rows[: args.pictures])
            same_kind += list(rows[args.pictures : args.pictures + TESTED])
        else:
            elsewhere += list(rows[:TESTED])
            if kind in unseen:
                far_half += list(rows[:TESTED])
            else:
                back += list(rows[TESTED : TESTED + args.background])
    model = make_recogniser("image", args.method).fit(X[train], scenes[train])
    tested = same_kind + elsewhere
    truth = np.r_[np.ones(len(same_kind)), np.zeros(len(elsewhere))]
    D, taught_D = model.describe(X[tested]), model.describe(X[train])
    proba = model.predict_proba(X[tested])
    named = np.asarray(model.scenes_)[proba.argmax(axis=1)]
    y = scenes[train]
    centres = {s: taught_D[y == s].mean(axis=0) for s in set(y)}
    centre = -np.array([np.linalg.norm(d - centres[n]) for d, n in zip(D, named, strict=True)])
    hsv_named = [np.flatnonzero(y == n) for n in named]
    peer = np.array(
        [
            np.max(unit(hsv[[t]]) @ unit(hsv[train][i]).T)
            for t, i in zip(tested, hsv_named, strict=True)
        ]
    )
    unknown = open_predict(model, X[tested])  # what the engine and `servant predict` go by
    # the background as an <elsewhere> class, scored on the untaught scenes it did not hold
    with_back = make_recogniser("image", args.method).fit(
        X[train + back], np.r_[y, [ELSEWHERE] * len(back)]
    )
    near_tested = same_kind + far_half
    near_truth = np.r_[np.ones(len(same_kind)), np.zeros(len(far_half))]
    p_else = with_back.predict_proba(X[near_tested])[:, list(with_back.scenes_).index(ELSEWHERE)]
    return {
        "taught": taught,
        "nearest taught picture": roc_auc_score(truth, nearest_cosine(D, named, taught_D, y)),
        "place centre": roc_auc_score(truth, centre),
        "head's top share": roc_auc_score(truth, proba.max(axis=1)),
        "with a background": roc_auc_score(near_truth, 1 - p_else),
        "plain peer (HSV nearest)": roc_auc_score(truth, peer),
        "own open set: unknown, untaught": float(np.mean(unknown[truth == 0] == UNKNOWN)),
        "own open set: unknown, taught kind": float(np.mean(unknown[truth == 1] == UNKNOWN)),
        "named rightly, taught kind": float(np.mean(named[truth == 1] == scenes[same_kind])),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data())
    parser.add_argument("--sizes", default="2,3,5")
    parser.add_argument("--draws", type=int, default=6)
    parser.add_argument("--pictures", type=int, default=6, help="pictures taught a place")
    parser.add_argument(
        "--background", type=int, default=100, help="pictures of each background scene"
    )
    parser.add_argument("--method", default="fisher-bovw", help="the picture method taught")
    args = parser.parse_args()
    root = args.data / "images" / "dev"
    if not root.is_dir():
        print(f"no real pictures at {root}; nothing to measure")
        return 0
    paths = sorted(p for folder in sorted(root.iterdir()) for p in sorted(folder.iterdir()))
    scenes = np.array([p.parent.name for p in paths])
    pictures = [read_picture(p) for p in paths]
    X = make_recogniser("image", args.method).featurize(pictures)
    hsv = np.sqrt(np.array([hsv_histogram(square_thumbnail(p)) for p in pictures]))
    print(
        f"{args.method}: {len(paths)} pictures of {len(set(scenes))} scenes; "
        f"{args.pictures} taught a place, "
        f"{TESTED} tested a scene, {args.draws} draws a size; ROC AUC, taught kind against "
        "untaught (0.5: no better than chance): mean [lowest, highest draw]"
    )
    for size in [int(s) for s in args.sizes.split(",")]:
        figures: dict[str, list[float]] = defaultdict(list)
        for draw in range(args.draws):
            result = one_draw(X, hsv, scenes, size, args, np.random.default_rng([size, draw]))
            print(f"  {size} places, draw {draw}: {', '.join(result.pop('taught'))}", flush=True)
            for name, value in result.items():
                figures[name].append(value)
        print(f"{size} places taught:")
        for name, values in figures.items():
            print(f"  {name:<36} {np.mean(values):.3f} [{min(values):.3f}, {max(values):.3f}]")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
