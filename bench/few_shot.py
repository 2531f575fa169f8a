"""Teach mode's figures on the whole real library: few-shot k = 1 / 3 / 10 of `kmeans-encoder`.

The first k windows (5 s each) of every recording of `../shared/data/audio/dev` teach it (k
presses of the teach key), the temporal test part of each recording (its last 40 %) is
recognised; balanced accuracy, mean ± std over seeds, and each figure against its target
(issues 11 and 23: 0.85 / 0.92 / 0.95, never lower at a larger k). The tests check the same
protocol on a small fixed subset (tests/test_kmeans_encoder.py); this bench reads everything.

    OMP_NUM_THREADS=1 python bench/few_shot.py [--data ../shared/data] [--seeds 5] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import shared_data  # noqa: E402
from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.evaluate import evaluate_audio  # noqa: E402
from servant_core.library import SceneLibrary  # noqa: E402

TARGETS = {1: 0.85, 3: 0.92, 10: 0.95}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data())
    parser.add_argument("--method", default="kmeans-encoder")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()
    root = args.data / "audio" / "dev"
    if not root.is_dir():
        print(f"no real recordings at {root}; nothing to measure")
        return 0
    library = SceneLibrary.scan(root)
    start = time.process_time()
    with library_noise_silenced():
        result = evaluate_audio(
            library, args.method, "fewshot", shots=tuple(TARGETS), seeds=args.seeds
        )
    n_recordings = len(library.recordings)
    print(
        f"{args.method}, few-shot on {n_recordings} recordings of {len(library.scenes)} scenes, "
        f"{args.seeds} seed(s), {time.process_time() - start:.0f} CPU s"
    )
    figures = []
    for row in result["rows"]:
        k, mean = row["shots"], row["balanced_accuracy"]
        spread = row.get("spread", {}).get("balanced_accuracy", {})
        std = f" ± {spread['std']:.3f}" if spread else ""
        verdict = "meets" if mean >= TARGETS[k] else "MISSES"
        print(f"  k={k:<3} balanced accuracy {mean:.3f}{std}  {verdict} the target {TARGETS[k]}")
        figures.append(mean)
    monotone = all(a <= b for a, b in zip(figures, figures[1:], strict=False))
    print(f"  never lower at a larger k: {'yes' if monotone else 'NO'}")
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
