"""Learned fusion vs the rule policies, with both senses and with each one withheld (issue 12).

The same encounters as `servant eval fusion`: each test window of the paired real data (scenes
with both recordings and pictures, temporal split) meets its scene's test pictures (file-order
split). The recognisers are fitted once; the learned fusion's net is trained on their held-out
opinions of the training parts, once per random state. Targets: precision >= 0.98 at a decision
rate above the parallel policy's, and a decision rate >= 0.80 with one sense withheld.

    python bench/learned_fusion.py [--audio-method kmeans-encoder] [--image-method bovw] [--seeds 5]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from fusion_latency import paired_library  # noqa: E402

from servant_core.evaluate import fusion_setup, score_fusion, score_learned  # noqa: E402
from servant_core.fusion import POLICIES, FusionConfig  # noqa: E402
from servant_core.recognisers import FRESH_METHODS  # noqa: E402

DROPS = (None, "audio", "image")


def figure(row: dict, key: str) -> str:
    spread = row.get("spread", {}).get(key)
    text = f"{row[key]:.3f}"
    return f"{text} ±{spread['std']:.3f} (min {spread['min']:.3f})" if spread else text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--audio-method", default=FRESH_METHODS["audio"])
    parser.add_argument("--image-method", default=FRESH_METHODS["image"])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--folds", type=int, default=4)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    config = FusionConfig()
    with tempfile.TemporaryDirectory() as tmp:
        library = paired_library(Path(tmp))
        start = time.perf_counter()
        setup = fusion_setup(library, args.audio_method, args.image_method, folds=args.folds)
        fitted_s = time.perf_counter() - start
    rows = []
    for drop in DROPS:
        for name in ("sequential", "parallel"):

            def make(name: str = name) -> object:
                return POLICIES[name](config)

            rows.append(
                {"policy": name, "drop_sense": drop, **score_fusion(setup, make, config, drop)}
            )
        start = time.perf_counter()
        learned = score_learned(setup, config, drop, args.seeds)
        learned["seconds"] = time.perf_counter() - start
        rows.append({"policy": "learned", "drop_sense": drop, **learned})
    if args.json:
        print(json.dumps(rows, indent=1))
        return
    n_train = {s: len(o.truth) for s, o in (setup.opinions or {}).items()}
    print(
        f"methods {args.audio_method}+{args.image_method}, scenes {','.join(setup.scenes)}, "
        f"{len(setup.truth)} test windows, net trained on held-out opinions {n_train} "
        f"({args.folds} folds; recognisers fitted and judged in {fitted_s:.0f} s), "
        f"seeds 0..{args.seeds - 1}"
    )
    print(f"{'senses':<12} {'policy':<11} {'decided':<28} {'right when decided':<28}")
    for row in rows:
        senses = f"no {row['drop_sense']}" if row["drop_sense"] else "both"
        print(
            f"{senses:<12} {row['policy']:<11} {figure(row, 'decision_rate'):<28} "
            f"{figure(row, 'precision'):<28}"
        )
    for row in rows:
        if row["policy"] == "learned":
            runs = row.get("per_seed", [row])
            print(
                f"learned, {row['drop_sense'] or 'both'}: thresholds "
                + ", ".join(f"{r['threshold']:.3f}" for r in runs if r["threshold"] is not None)
                + f"; leaned on (seed 0) {runs[0]['leaned_on']}; {row['seconds']:.1f} s"
            )


if __name__ == "__main__":
    main()
