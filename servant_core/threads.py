"""One thread for the numerical libraries' own pools (OpenMP, OpenBLAS, MKL), unless the user's
environment already sizes them.

The pools are sized when the libraries load, so this runs before numpy is imported.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")

POOLS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def one_thread_pools() -> None:
    """Each pool one thread, where the environment does not say otherwise."""
    for name in POOLS:
        os.environ.setdefault(name, "1")


def results_in_order(jobs: Sequence[Callable[[], T]]) -> Iterator[T]:
    """Each job's result, in the jobs' order, the jobs run on a thread a core meanwhile.

    For start-up work that is mostly numpy and scipy, which let go of the interpreter's lock in
    their large calls. A job's exception is raised where its result is due; a reader that stops
    early, or an interrupt, cancels the jobs not yet begun and waits for the running ones.
    """
    workers = max(1, min(len(jobs), os.cpu_count() or 1))
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="servant-start")
    try:
        futures = [pool.submit(job) for job in jobs]
        for future in futures:
            yield future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
