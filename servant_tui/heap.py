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
def _glibc(name: str) -> Callable[..., int] | None:
    """A function of the C library's allocator, or None where it is not glibc (musl, macOS)."""
    try:
        return getattr(ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6"), name)
    except (OSError, AttributeError):
        return None


# glibc gives each new thread a heap of its own ("arena") up to 8 per core; a page freed in one
# stays there. The app runs a dozen threads (the engine's senses, Textual's, the workers) whose
# allocations are brief and which mostly wait on the GIL anyway: two heaps serve them as well and
# keep less memory idle (the headless demo after 100 s: 245 MB with two, 255 MB by default).
ARENAS = 2
_M_ARENA_MAX = -8  # mallopt's parameter number, from glibc's malloc.h


def limit_heaps(arenas: int = ARENAS) -> None:
    """Let threads created from now on share `arenas` C heaps (glibc); elsewhere do nothing.
    Call it at start-up, before the threads that allocate most are started."""
    mallopt = _glibc("mallopt")
    if mallopt is not None:
        mallopt(_M_ARENA_MAX, arenas)


def release_free_heap() -> None:
    """Return the C heaps' free pages to the system (glibc); elsewhere do nothing."""
    trim = _glibc("malloc_trim")
    if trim is not None:
        trim(0)
