"""Which feature rows a recogniser may be given: numbers, each within `FEATURE_LIMIT`.

Every sense's samples are checked for their range where they are read; this is the last check
before a fit, a prediction or a fold-in, so that no window whose features came out as NaN or
infinity (or so large that a distance squares them into infinity) ever reaches scikit-learn,
which would refuse the whole batch with a traceback.
"""

from __future__ import annotations

import numpy as np

from servant_core.errors import ServantError

# Far above any real feature (the paper's FFT amplitudes of a 60 s window at ±1000 full scale
# are under 1e10), far below where a squared distance in float32 overflows (3.4e38).
FEATURE_LIMIT = 1e15


def usable_rows(X: np.ndarray) -> np.ndarray:
    """A boolean per row of `X` (n, ...): every value a number within ±`FEATURE_LIMIT`."""
    X = np.asarray(X)
    if len(X) == 0:
        return np.zeros(0, dtype=bool)
    if X.dtype.kind in "biu":  # whole numbers are finite, and a feature never that large
        return np.ones(len(X), dtype=bool)
    # in the rows' own type (float16 descriptors cannot hold the limit itself)
    limit = min(FEATURE_LIMIT, float(np.finfo(X.dtype).max))
    return np.all(np.abs(X.reshape(len(X), -1)) <= limit, axis=1)


class UnusableWindow(ServantError):
    """A window whose features are not usable numbers; the window is skipped, nothing else."""


def checked_rows(X: np.ndarray, what: str) -> np.ndarray:
    """`X` if every row is usable; else `UnusableWindow` naming `what` (a window, a sense)."""
    if not np.all(usable_rows(X)):
        raise UnusableWindow(
            f"{what}: skipped a window whose features are not finite numbers (samples beyond "
            "the sense's range?)"
        )
    return X
