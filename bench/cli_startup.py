"""How long the command line takes to answer, against the interpreter starting and doing nothing.

`servant --help` (target: 0.5 s on the project's machine), `servant train --help`, and
`servant demo --headless --fast` (target: 10 s), each the median of a few runs, printed beside
`python -c pass` measured in the same run, and as a ratio to it: a shared, loaded machine slows
every process alike, so the ratio is the figure to compare between runs. A command that imports
more than it needs shows here first.
Run: `python bench/cli_startup.py [--demo]` (the demo's walk takes a while; off by default).
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import REPO  # noqa: E402

RUNS = 5


def median_s(argv: list[str], runs: int = RUNS) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        subprocess.run(argv, cwd=REPO, capture_output=True, check=True)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    servant = [sys.executable, "-m", "servant_tui"]
    nothing = median_s([sys.executable, "-c", "pass"])
    rows = [("python -c pass", nothing)]
    rows.append(("servant --help", median_s([*servant, "--help"])))
    rows.append(("servant train --help", median_s([*servant, "train", "--help"])))
    if "--demo" in sys.argv:
        rows.append(
            (
                "servant demo --headless --fast",
                median_s([*servant, "demo", "--headless", "--fast"], 3),
            )
        )
    print(f"{'command':<34} {'median s':>9} {'x python -c pass':>17}")
    for name, seconds in rows:
        print(f"{name:<34} {seconds:9.3f} {seconds / nothing:17.1f}")


if __name__ == "__main__":
    main()
