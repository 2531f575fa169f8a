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

POOLS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def one_thread_pools() -> None:
    """Each pool one thread, where the environment does not say otherwise."""
    for name in POOLS:
        os.environ.setdefault(name, "1")
