"""How a `servant teach` session scales with the number of scene labels taught (issue 13, 8).

Runs the real CLI handler (`servant teach`, no arm) on a scripted session of N labels, each with a
typed angle, into a fresh records file, and times its two phases separately: the training phase
(each answer appended to the records file, atomically) and the learning (the network's fit).
Also prints the records file's size. A session that grows quadratically shows it as the time per
label rising with N.
Run: `python bench/teach_records.py [N ...]` (default 50 100 200 300).
"""

from __future__ import annotations

import argparse
import io
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from servant_core.actions import learner as learner_module  # noqa: E402
from servant_core.cli import build_parser  # noqa: E402
from servant_core.cli.arm import run_teach  # noqa: E402


def session(n: int, folder: Path) -> tuple[float, float, int]:
    """Seconds in the training phase, seconds learning, and the records file's bytes."""
    records = folder / f"records-{n}.json"
    script = "".join(f"scene{i}\n{i % 90}\n" for i in range(n)) + "\n"
    args = build_parser().parse_args(
        ["teach", "--records", str(records), "--learner", str(folder / f"learner-{n}.npz")]
    )
    fit = learner_module.ActionLearner.fit
    spent = {"fit": 0.0}

    def timed_fit(self, *a, **k):
        start = time.perf_counter()
        try:
            return fit(self, *a, **k)
        finally:
            spent["fit"] += time.perf_counter() - start

    learner_module.ActionLearner.fit = timed_fit  # type: ignore[method-assign]
    try:
        start = time.perf_counter()
        run_teach(args, io.StringIO(script), io.StringIO())
        total = time.perf_counter() - start
    finally:
        learner_module.ActionLearner.fit = fit  # type: ignore[method-assign]
    return total - spent["fit"], spent["fit"], records.stat().st_size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sizes", nargs="*", type=int, default=[50, 100, 200, 300])
    sizes = parser.parse_args().sizes
    with tempfile.TemporaryDirectory() as tmp:
        os.environ["SERVANT_DATA_DIR"] = tmp  # never the user's own data dir
        print(
            f"{'labels':>6} {'training phase s':>17} {'ms/label':>9} {'learning s':>11} "
            f"{'file KiB':>9}"
        )
        for n in sizes:
            phase, fit, size = session(n, Path(tmp))
            print(
                f"{n:>6} {phase:>17.2f} {1000 * phase / n:>9.1f} {fit:>11.2f} {size / 1024:>9.0f}"
            )


if __name__ == "__main__":
    main()
