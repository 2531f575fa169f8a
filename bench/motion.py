"""Motion and ambient recognition: balanced accuracy on synthesised windows over several seeds,
and, given --root, cross-validated on a folder of recorded CSV logs (ROOT/<scene>/*.imu.csv,
*.ambient.csv).

    .venv/bin/python bench/motion.py [--seeds 5] [--windows 20] [--root ROOT]

No real labelled motion data is at hand: the synthesised figures say how the method does on the
demo's own signals, not on people.
"""

from __future__ import annotations

import argparse
import statistics
import time

from servant_core.errors import ServantError
from servant_core.evaluate_motion import evaluate_library, evaluate_synthesised


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--windows", type=int, default=20, help="windows per scene and set")
    parser.add_argument("--root", help="a folder of recorded logs, ROOT/<scene>/*.imu.csv")
    parser.add_argument("--folds", type=int, default=5)
    args = parser.parse_args()
    for sense in ("motion", "ambient"):
        start = time.perf_counter()
        scores = [evaluate_synthesised(sense, seed, args.windows) for seed in range(args.seeds)]
        accuracy = [s.balanced_accuracy for s in scores]
        spread = statistics.stdev(accuracy) if len(accuracy) > 1 else 0.0
        print(
            f"{sense} synthesised, {args.seeds} seeds x {scores[0].n_windows} test windows: "
            f"balanced accuracy {statistics.mean(accuracy):.3f} ± {spread:.3f} "
            f"(min {min(accuracy):.3f}), decision rate "
            f"{statistics.mean(s.decision_rate for s in scores):.3f}, precision "
            f"{statistics.mean(s.precision for s in scores):.3f} "
            f"[{time.perf_counter() - start:.1f} s]"
        )
        if args.root:
            try:
                result, skipped = evaluate_library(args.root, sense, args.folds)
            except ServantError as error:
                print(f"{sense} on {args.root}: {error}")
                continue
            print(
                f"{sense} on {args.root} ({result.n_windows} windows, {args.folds}-fold by file): "
                f"balanced accuracy {result.balanced_accuracy:.3f}, decision rate "
                f"{result.decision_rate:.3f}, precision {result.precision:.3f}"
            )
            for line in skipped:
                print(f"  skipped: {line}")


if __name__ == "__main__":
    main()
