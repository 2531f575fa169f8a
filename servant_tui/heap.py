"""Give the C heap's free memory back to the system after the few jobs that need a lot at once.

Training (the demo's start, a retrain) and evaluating allocate large arrays for a few seconds.
glibc keeps what they freed inside its heaps for reuse: its threshold for giving large blocks
their own mapping (returned at once when freed) rises to the size of the largest one freed, so
later large arrays come from the heap and stay there. A retrain left the TUI ~15 MB bigger for
good. `malloc_trim(0)` returns the free pages of every heap; the memory in use is untouched.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
from collections.abc import Callable


@functools.cache
def _malloc_trim() -> Callable[[int], int] | None:
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc (musl, macOS): nothing to give back this way
        return None


def release_free_heap() -> None:
    """Return the C heaps' free pages to the system (glibc); elsewhere do nothing."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
