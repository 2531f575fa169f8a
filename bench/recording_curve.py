"""How a recording never heard is recognised as the number of recordings a scene grows.

The leave-one-recording-out target (≥ 0.60 balanced accuracy) is far from every method on
`../shared/data`, where a scene has 2–5 recordings. This bench asks whether that is the method or
the data: over the scenes with at least `--max-train` + 1 recordings (cafe, street, vehicle on
the dev set), each recording is left out in turn and the model trains on `n` recordings of every
one of those scenes (its own scene's drawn from the others), for n = 1 … `--max-train`. Each
(left-out recording, n) is drawn `--draws` times; the windows of every fold and draw are pooled
into one balanced accuracy per n (chance: 1 / number of scenes). The same draws serve every
method: `kmeans-encoder` and the log-mel + logistic-regression peer of `bench/peers.py`.

    OMP_NUM_THREADS=1 python bench/recording_curve.py [--data ../shared/data] [--draws 6]
        [--max-train 3] [--seed 0] [--param C=0.5 ...]
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
from servant_core.library import SceneLibrary, WindowFeatures  # noqa: E402
from servant_core.recognisers import make_audio_recogniser  # noqa: E402

PEER = "log-mel(64) mean/std + logistic regression"
METHOD = "kmeans-encoder"


def draws_of(
    wf: WindowFeatures, scenes: list[str], n: int, draws: int, rng: np.random.Generator
) -> list[tuple[int, list[int]]]:
    """(left-out recording, training recordings) pairs: n recordings of every scene, none of
    them the left-out one."""
    by_scene = {s: sorted(set(wf.recording[wf.scenes == s].tolist())) for s in scenes}
    plan = []
    for scene in scenes:
        for left_out in by_scene[scene]:
            for _ in range(draws):
                train: list[int] = []
                for recs in by_scene.values():
                    pool = [r for r in recs if r != left_out]
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
            model = make().fit(wf.features[fit_rows], wf.scenes[fit_rows])
            said += [str(s) for s in model.predict(wf.features[test_rows])]
            truth += [str(s) for s in wf.scenes[test_rows]]
        figures.append(float(balanced_accuracy_score(truth, said)))
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data(), help="the shared data root")
    parser.add_argument("--draws", type=int, default=6, help="draws per left-out recording")
    parser.add_argument("--max-train", type=int, default=3, help="largest n")
    parser.add_argument("--seed", type=int, default=0, help="random state of the draws")
    parser.add_argument(
        "--param", action="append", default=[], help=f"{METHOD}'s name=value (JSON value)"
    )
    args = parser.parse_args()
    params = {k: json.loads(v) for k, v in (p.split("=", 1) for p in args.param)}
    library = SceneLibrary.scan(args.data / "audio" / "dev")
    counts = Counter(r.scene for r in library.recordings)
    scenes = sorted(s for s, c in counts.items() if c > args.max_train)
    # Only the recordings of those scenes are read and featurised.
    library = replace(library, recordings=[r for r in library.recordings if r.scene in scenes])
    encoder = make_audio_recogniser(METHOD, rate=RATE)
    features = featurize_all(library, {METHOD: encoder.featurize, PEER: PEERS[PEER][0]})
    wf = features[METHOD]
    plans = {
        n: draws_of(wf, scenes, n, args.draws, np.random.default_rng([args.seed, n]))
        for n in range(1, args.max_train + 1)
    }
    print(
        f"scenes: {', '.join(f'{s} ({counts[s]})' for s in scenes)}; chance {1 / len(scenes):.3f}; "
        f"{args.draws} draws per left-out recording"
    )
    print(f"{'method':<44} " + " ".join(f"n={n:<5}" for n in plans))
    makers: dict[str, Callable[[], Any]] = {
        METHOD: lambda: make_audio_recogniser(METHOD, rate=RATE, random_state=args.seed, **params),
        PEER: lambda: PEERS[PEER][1](args.seed),
    }
    for name, make in makers.items():
        part = with_source_column(features[name]) if name == PEER else features[name]
        start = time.perf_counter()
        figures = curve(part, plans, make)
        print(
            f"{name:<44} "
            + " ".join(f"{f:<7.3f}" for f in figures)
            + f"  ({time.perf_counter() - start:.0f} s)",
            flush=True,
        )


if __name__ == "__main__":
    with library_noise_silenced():  # mpg123 warns of one real MP3 on descriptor 2
        main()
