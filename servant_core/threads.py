"""One thread for the numerical libraries' own pools (OpenMP, OpenBLAS, MKL), unless the user's
environment already sizes them.

Servant's numbers are many small arrays (a 5 s window, a picture, a K-Means of a few hundred
rows) on a small machine that already runs a dozen threads of its own (the senses, the arm, the
terminal). A pool thread per core then mostly spins waiting for work that another Python thread
holds the processor for: on the 2-core project machine under load, `servant demo --headless
--fast` took 18–55 s of CPU with the default pools (one SVD of the picture recogniser's fit took
3 s instead of 0.1 s) and 11–12 s with one thread each. The pools are sized when the libraries
load, so this runs before numpy is imported.
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
    their large calls: on the project's two cores the demo's training scenes were synthesised in
    1.15 s instead of 1.7 s (before their formants were made cheaper). Its two fits side by side
    saved another 0.6 s, but each thread that calls the BLAS gets a buffer of its own, and the
    app's peak memory went 244 → 258 MB, past its 250 MB target: they stay one after the other.
    A job's exception is raised where its result is due; a reader that stops early, or an
    interrupt, cancels the jobs not yet begun and waits for the running ones.
    """
    workers = max(1, min(len(jobs), os.cpu_count() or 1))
    pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="servant-start")
    try:
        futures = [pool.submit(job) for job in jobs]
        for future in futures:
            yield future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
