"""A developer option to find what makes a long-running TUI grow: `SERVANT_MEMTRACE=FILE`.

With it set, `servant` (and `servant demo`) starts `tracemalloc` and a daemon thread that appends
to FILE every `SERVANT_MEMTRACE_EVERY` seconds (default 60), first after `SERVANT_MEMTRACE_AFTER`
(default the same): VmRSS, traced memory, the lines, call paths, object types and `lru_cache`
entries that grew most, and glibc's `mallinfo2`. `SERVANT_MEMTRACE_FRAMES=0` leaves tracemalloc
off and reports the rest. Off unless asked for: tracing costs CPU and memory.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import gc
import os
import threading
import time
import tracemalloc
from collections import Counter
from pathlib import Path

FRAMES = 12  # frames kept per allocation: enough to see which of our lines called a library


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


class MallInfo2(ctypes.Structure):
    """glibc's `struct mallinfo2` (glibc 2.33 and later), summed over all malloc arenas."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in (
            "arena",
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",
            "usmblks",
            "fsmblks",
            "uordblks",
            "fordblks",
            "keepcost",
        )
    ]


def malloc_text() -> str:
    """What the C allocator holds: in use, free inside its heaps (fragmentation if it grows while
    in use does not) and mapped directly; empty where there is no glibc `mallinfo2`."""
    try:
        mallinfo2 = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallinfo2
    except (OSError, AttributeError):
        return ""
    mallinfo2.restype = MallInfo2
    info = mallinfo2()
    mb = 2**20
    return (
        f"  malloc: in use {info.uordblks / mb:.1f} MB, free in heaps {info.fordblks / mb:.1f} MB,"
        f" mmapped {info.hblkhd / mb:.1f} MB"
    )


def census() -> tuple[Counter[str], Counter[str]]:
    """(live objects the collector tracks, by type; entries of each `functools.lru_cache`)."""
    types: Counter[str] = Counter()
    caches: Counter[str] = Counter()
    for o in gc.get_objects():
        types[type(o).__qualname__] += 1
        if isinstance(o, functools._lru_cache_wrapper):
            caches[f"{o.__module__}.{o.__qualname__}"] = o.cache_info().currsize
    return types, caches


def grown(now: Counter[str], first: Counter[str], most: int) -> list[str]:
    return [
        f"{n:+d} {k}" for k, n in Counter({k: now[k] - first[k] for k in now}).most_common(most)
    ]


def start_from_environment() -> None:
    """Start the tracing thread if `SERVANT_MEMTRACE` names a file; otherwise do nothing."""
    path = os.environ.get("SERVANT_MEMTRACE")
    if not path:
        return
    every = float(os.environ.get("SERVANT_MEMTRACE_EVERY", "60"))
    after = float(os.environ.get("SERVANT_MEMTRACE_AFTER", str(every)))
    frames = int(os.environ.get("SERVANT_MEMTRACE_FRAMES", str(FRAMES)))
    if frames > 0:
        tracemalloc.start(frames)
    threading.Thread(target=_trace, args=(Path(path), every, after), daemon=True).start()


def _trace(path: Path, every: float, after: float) -> None:
    start = time.monotonic()
    first: tracemalloc.Snapshot | None = None
    first_census: tuple[Counter[str], Counter[str]] | None = None
    time.sleep(after)
    while True:
        tracing = tracemalloc.is_tracing()
        snapshot = (
            tracemalloc.take_snapshot().filter_traces(
                [tracemalloc.Filter(False, tracemalloc.__file__)]
            )
            if tracing
            else None
        )
        types, caches = census()
        minutes = (time.monotonic() - start) / 60
        traced = f"  traced {tracemalloc.get_traced_memory()[0] / 2**20:.1f} MB" if tracing else ""
        lines = [f"== {minutes:.1f} min  rss {rss_mb():.1f} MB{traced}{malloc_text()}"]
        if first_census is None:
            first, first_census = snapshot, (types, caches)
        else:
            if snapshot is not None and first is not None:
                lines.append("-- lines grown most since the first snapshot")
                lines.extend(str(stat) for stat in snapshot.compare_to(first, "lineno")[:10])
                lines.append("-- the call paths behind them")
                for stat in snapshot.compare_to(first, "traceback")[:8]:
                    lines.append(f"{stat.size_diff / 1024:+.1f} KiB {stat.count_diff:+d} blocks")
                    lines.extend(f"    {frame}" for frame in stat.traceback.format())
            lines.append("-- object types grown most since the first snapshot")
            lines.extend(grown(types, first_census[0], 15))
            lines.append("-- lru_cache entries grown most (Rich's and Textual's caches among them)")
            lines.extend(grown(caches, first_census[1], 8))
        with path.open("a", encoding="utf-8") as out:
            out.write("\n".join(lines) + "\n")
        time.sleep(every)
