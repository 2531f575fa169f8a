"""How far any threshold on `birdnet`'s scores could carry a taught place (issue 37).

On the wearer's walk's draws (the same places, recordings and stays as `bench/wearer_day.py
--half H`, through `bench/teach_augment.py`'s cached embeddings; six taught windows a place, no
engine, no smoothing), per window:

- `today`: the product's own names (`answers`: the head, somewhere else, the nearest taught
  window's cosine): right at the taught places' later windows, named (any taught place) at
  untaught places;
- `ceiling`: for a score, the threshold that lets 2 % of *this half's own* untaught windows
  through, chosen on the windows it is then read on (an oracle: what no rule that must be chosen
  beforehand can beat with that score), and the share of taught windows named right above it.
  Scores: the open probability of the likeliest place (`open`), the cosine to its nearest
  taught window (`cosine`), that cosine over the median of the taught windows' own nearest
  cosines, leave one out (`cosine / own`);
- `background`: a threshold each library calibrates itself, from what it was taught: the largest
  open probability any window of the shipped background reaches in a model whose background
  leaves its recording out (`background_exclude`, six folds by recording); a window is its
  likeliest place above it;
- `self-taught`: the walk in order, each window the product names a place at 90 % or more folded
  into that place (at most 24 a place), so that a place follows its own sound as it drifts.

    OMP_NUM_THREADS=1 python bench/open_ceiling.py [--halves 0,1] [--sizes 2,3,5] [--draws 6]
        [--cache DIR]
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import teach_augment  # noqa: E402
from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.recognisers import UNKNOWN  # noqa: E402
from servant_core.recognisers.birdnet import BirdnetAcousticRecogniser  # noqa: E402
from servant_core.recognisers.centroids import unit_rows  # noqa: E402

UNTAUGHT_LET_THROUGH = 0.02
BACKGROUND_FOLDS = 6
SELF_SURE = 90.0
SELF_AT_MOST = 24
KINDS = ("taught", "untaught")


def held_out_background(X: np.ndarray, y: np.ndarray, background: Any) -> np.ndarray:
    """The largest open probability of each window of the `background`, from a model taught
    windows `X` of places `y` with that window's recording kept out of its background
    (`background_exclude`, `BACKGROUND_FOLDS` folds by recording)."""
    names = np.unique(background.recordings)
    folds = np.arange(len(names)) % BACKGROUND_FOLDS
    out = np.empty(len(background.recordings))
    for fold in range(BACKGROUND_FOLDS):
        kept_out = names[folds == fold]
        held = np.isin(background.recordings, kept_out)
        model = BirdnetAcousticRecogniser(background_exclude=tuple(kept_out)).fit(X, y)
        frames = background.frames[held].reshape(int(held.sum()), -1)
        out[held] = model._open_proba(model._space(frames)).max(axis=1)
    return out


def own_cosine(model: BirdnetAcousticRecogniser, place: str) -> float:
    """The median of `place`'s taught windows' nearest other taught window's cosine."""
    taught = model._taught_rows(place)
    near = taught @ taught.T
    np.fill_diagonal(near, -1.0)
    return float(np.median(near.max(axis=1)))


def window_scores(model: BirdnetAcousticRecogniser, X: np.ndarray) -> dict[str, np.ndarray]:
    D = model._space(X)
    open_p = model._open_proba(D)
    names = np.array(model.classes_)[np.argmax(open_p, axis=1)]
    rows = unit_rows(D)
    cosine = np.array([np.max(rows[i] @ model._taught_rows(n).T) for i, n in enumerate(names)])
    own_of = {place: own_cosine(model, place) for place in model.classes_}  # once a place
    own = np.array([own_of[n] for n in names])
    return {
        "names": names,
        "today": model.answers(X)[0],
        "open": open_p.max(axis=1),
        "cosine": cosine,
        "cosine / own": cosine / own,
    }


def self_taught(model: BirdnetAcousticRecogniser, X: np.ndarray) -> np.ndarray:
    """The walk's names in order, each sure window folded into its place (module docstring)."""
    names, added = [], defaultdict(int)
    for row in X:
        name, confidence, _ = model.answers(row[None])
        names.append(name[0])
        if name[0] != UNKNOWN and confidence[0] >= SELF_SURE and added[name[0]] < SELF_AT_MOST:
            model.fold_in(row[None], [name[0]])
            added[name[0]] += 1
    return np.array(names)


def measure_draw(
    plan: dict[str, Any], X_all: np.ndarray, background: Any
) -> dict[str, tuple[float, float]]:
    """{row: (right at taught, named at untaught)} of one draw; the ceiling rows' second figure
    is their threshold."""
    ids, y = plan["audio"]
    ids = np.asarray(ids).reshape(-1)
    stays = [s for s in plan["stays"] if s.kind in KINDS]
    windows = np.concatenate([np.asarray(s.windows).reshape(-1) for s in stays])
    kinds = np.concatenate([[s.kind] * len(s.windows) for s in stays])
    truth = np.concatenate([[s.truth or ""] * len(s.windows) for s in stays]).astype(str)
    taught, untaught = kinds == "taught", kinds == "untaught"
    y = np.asarray(y).astype(str)
    model = BirdnetAcousticRecogniser().fit(X_all[ids], y)
    scores = window_scores(model, X_all[windows])
    rightly = scores["names"] == truth

    def figures(names: np.ndarray) -> tuple[float, float]:
        return float(np.mean((names == truth)[taught])), float(
            np.mean((names != UNKNOWN)[untaught])
        )

    out = {"today": figures(scores["today"])}
    for score in ("open", "cosine", "cosine / own"):
        threshold = float(np.quantile(scores[score][untaught], 1 - UNTAUGHT_LET_THROUGH))
        right = float(np.mean((rightly & (scores[score] > threshold))[taught]))
        out[f"ceiling, {score}"] = (right, threshold)
    limit = held_out_background(X_all[ids], y, background).max()
    out["background"] = figures(np.where(scores["open"] > limit, scores["names"], UNKNOWN))
    out["self-taught"] = figures(self_taught(model, X_all[windows]))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    teach_augment.add_walk_options(parser)
    parser.add_argument("--halves", default="0,1")
    args = parser.parse_args()
    if not (args.data / "audio" / "dev").is_dir():
        print(f"no real data at {args.data}; nothing to measure")
        return 0
    warnings.simplefilter("ignore")  # scikit-learn's convergence chatter
    model = BirdnetAcousticRecogniser()
    with library_noise_silenced():
        recordings = teach_augment.embedded(args.data, model, args.cache)
    X_all = np.concatenate([r.X for r in recordings]).astype(np.float64)
    found = model._background()
    if found is None:
        raise SystemExit("birdnet's background file is missing; nothing to measure")
    for half in [int(h) for h in args.halves.split(",")]:
        data = teach_augment.walk_data(args.data, recordings, half)
        for size in [int(s) for s in args.sizes.split(",")]:
            rows: dict[str, list[tuple[float, float]]] = defaultdict(list)
            for draw in range(args.draws):
                plan = teach_augment.plan(data, size, draw)
                if not any(s.kind == "taught" for s in plan["stays"]):
                    continue  # no later windows of the taught recordings to walk
                for row, pair in measure_draw(plan, X_all, found).items():
                    rows[row].append(pair)
            print(f"half {half}, {size} places, {len(rows['today'])} draws: mean (range)")
            for row, pairs in rows.items():
                right, second = np.array(pairs).T
                what = "threshold" if row.startswith("ceiling") else "named at untaught"
                print(
                    f"  {row:<22} right at taught {teach_augment.spread(list(right))}  "
                    f"{what} {teach_augment.spread(list(second))}",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
