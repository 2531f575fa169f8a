"""How a recording never heard is recognised as the number of recordings a scene grows.

This bench asks whether a place never heard is the method or the data: over the scenes with
more than n recordings for every n asked (cafe, street, vehicle on the 84-recording dev set for
n up to 10), a recording is left out in turn and the model trains on `n` recordings of every one
of those scenes, drawn at random, for each n of `--ns` (default 1 … `--max-train`). With
`--exclude source` (the default) no training recording shares the left-out one's source (the
file name up to its first `-`), in any scene: a place never heard through a microphone never
heard; `--exclude recording` only keeps the left-out recording itself out. `--left-out K` leaves
out K recordings a scene (drawn once, the same for every n) rather than all. Each (left-out
recording, n) is drawn `--draws` times; the windows of every fold and draw are pooled into one
balanced accuracy per n (chance: 1 / number of scenes). The same draws serve every method:
`kmeans-encoder` and the peers of `bench/peers.py` (their C chosen by CV grouped by source).

    OMP_NUM_THREADS=1 python bench/recording_curve.py [--data ../shared/data] [--draws 6]
        [--max-train 3 | --ns 1,2,4,10] [--exclude source|recording] [--left-out K]
        [--methods kmeans-encoder,log-mel,MFCC] [--seed 0] [--param C=0.5 ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from sklearn.metrics import balanced_accuracy_score

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import shared_data  # noqa: E402
from peers import PEERS, RATE, featurize_all, with_source_column  # noqa: E402

from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.evaluate import source_of  # noqa: E402
from servant_core.library import SceneLibrary, WindowFeatures, visits_of  # noqa: E402
from servant_core.recognisers import make_audio_recogniser  # noqa: E402
from servant_core.recognisers.base import fit_visits  # noqa: E402

METHOD = "kmeans-encoder"


def pools(wf: WindowFeatures, scenes: list[str], exclude: str) -> dict[int, dict[str, list[int]]]:
    """For each recording of `scenes` left out, the recordings of each scene a fold may train
    on: all but the left-out one, or (`exclude` "source") all but its source's."""
    group = [
        source_of(r.path) if exclude == "source" else str(i) for i, r in enumerate(wf.recordings)
    ]
    by_scene = {s: sorted(set(wf.recording[wf.scenes == s].tolist())) for s in scenes}
    return {
        left_out: {
            s: [r for r in recs if group[r] != group[left_out]] for s, recs in by_scene.items()
        }
        for recs_of_scene in by_scene.values()
        for left_out in recs_of_scene
    }


def draws_of(
    allowed: dict[int, dict[str, list[int]]],
    left_outs: list[int],
    n: int,
    draws: int,
    rng: np.random.Generator,
) -> list[tuple[int, list[int]]]:
    """(left-out recording, training recordings) pairs: n recordings of every scene, each drawn
    from what the left-out one allows."""
    plan = []
    for left_out in left_outs:
        for _ in range(draws):
            train: list[int] = []
            for pool in allowed[left_out].values():
                train += rng.choice(pool, n, replace=False).tolist()
            plan.append((left_out, train))
    return plan


def curve(
    wf: WindowFeatures, plans: dict[int, list[tuple[int, list[int]]]], make: Callable[[], Any]
) -> list[float]:
    """Pooled balanced accuracy of each n's plan."""
    figures = []
    for plan in plans.values():
        truth: list[str] = []
        said: list[str] = []
        for left_out, train in plan:
            fit_rows = np.isin(wf.recording, train)
            test_rows = wf.recording == left_out
            model = fit_visits(
                make(), wf.features[fit_rows], wf.scenes[fit_rows], visits_of(wf)[fit_rows]
            )
            said += [str(s) for s in model.predict(wf.features[test_rows])]
            truth += [str(s) for s in wf.scenes[test_rows]]
        figures.append(float(balanced_accuracy_score(truth, said)))
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data(), help="the shared data root")
    parser.add_argument("--draws", type=int, default=6, help="draws per left-out recording")
    parser.add_argument("--max-train", type=int, default=3, help="largest n (without --ns)")
    parser.add_argument(
        "--ns", type=lambda t: [int(n) for n in t.split(",")], help="the n to draw, e.g. 1,2,4,10"
    )
    parser.add_argument(
        "--exclude",
        choices=("source", "recording"),
        default="source",
        help="what a fold never trains on: the left-out recording's source, or only itself",
    )
    parser.add_argument("--left-out", type=int, help="recordings left out a scene (default: all)")
    parser.add_argument(
        "--methods",
        type=lambda t: tuple(t.split(",")),
        default=(METHOD, "log-mel"),
        help=f"comma-separated: {METHOD} and peers by the start of their name (MFCC, log-mel)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random state of the draws")
    parser.add_argument(
        "--param", action="append", default=[], help=f"{METHOD}'s name=value (JSON value)"
    )
    args = parser.parse_args()
    ns = args.ns or list(range(1, args.max_train + 1))
    params = {k: json.loads(v) for k, v in (p.split("=", 1) for p in args.param)}
    library = SceneLibrary.scan(args.data / "audio" / "dev")
    counts = Counter(r.scene for r in library.recordings)
    scenes = sorted(s for s, c in counts.items() if c > max(ns))
    # Only the recordings of those scenes are read and featurised.
    library = replace(library, recordings=[r for r in library.recordings if r.scene in scenes])
    peers = [name for name in PEERS if name.startswith(args.methods)]
    featurizers = {name: PEERS[name][0] for name in peers}
    if METHOD in args.methods:
        featurizers[METHOD] = make_audio_recogniser(METHOD, rate=RATE).featurize
    features = featurize_all(library, featurizers)
    wf = next(iter(features.values()))
    allowed = pools(wf, scenes, args.exclude)
    # A left-out recording whose source leaves a scene fewer than max(ns) recordings is skipped.
    eligible = {
        s: [
            r
            for r, p in allowed.items()
            if wf.recordings[r].scene == s and min(map(len, p.values())) >= max(ns)
        ]
        for s in scenes
    }
    pick = np.random.default_rng([args.seed, 1000])
    left_outs = sorted(
        r
        for recs in eligible.values()
        for r in (
            recs
            if args.left_out is None or args.left_out >= len(recs)
            else pick.choice(recs, args.left_out, replace=False).tolist()
        )
    )
    plans = {
        n: draws_of(allowed, left_outs, n, args.draws, np.random.default_rng([args.seed, n]))
        for n in ns
    }
    print(
        f"scenes: {', '.join(f'{s} ({counts[s]})' for s in scenes)}; chance {1 / len(scenes):.3f}; "
        f"left out: {len(left_outs)} recordings ({args.exclude} never trained on), "
        f"{args.draws} draws each"
    )
    print(f"{'method':<44} " + " ".join(f"n={n:<5}" for n in plans))
    makers: dict[str, Callable[[], Any]] = {
        METHOD: lambda: make_audio_recogniser(METHOD, rate=RATE, random_state=args.seed, **params)
    }
    makers.update({name: lambda name=name: PEERS[name][1](args.seed) for name in peers})
    for name, part in features.items():
        if name in PEERS:
            part = with_source_column(part)
        start = time.perf_counter()
        figures = curve(part, plans, makers[name])
        print(
            f"{name:<44} "
            + " ".join(f"{f:<7.3f}" for f in figures)
            + f"  ({time.perf_counter() - start:.0f} s)",
            flush=True,
        )


if __name__ == "__main__":
    with library_noise_silenced():  # mpg123 warns of one real MP3 on descriptor 2
        main()
