"""What the benchmark scripts share: where the real data is, and a median timer."""

from __future__ import annotations

import os
import statistics
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def shared_data() -> Path:
    """$SERVANT_SHARED_DATA, else `../shared/data` beside the repository (it may not exist)."""
    return Path(os.environ.get("SERVANT_SHARED_DATA", REPO.parent / "shared" / "data"))


def median_ms(fn: Callable[[], object], repeats: int = 30) -> float:
    """Median wall time of `fn` in milliseconds, after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1000)
    return statistics.median(times)
