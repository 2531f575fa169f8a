"""A ring buffer of mono samples, addressed by absolute sample index.

The engine cuts windows and spectrum frames out of it by absolute position (sample `n` since the
stream started), so a window is exactly samples [k·W, (k+1)·W) whatever the block sizes were, and
a spectrum frame copies only its own 2048 samples, never the whole buffer.
"""

from __future__ import annotations

import threading

import numpy as np


class RingBuffer:
    def __init__(self, capacity: int) -> None:
        if capacity <= 0:
            raise ValueError("capacity must be positive")
        self.capacity = capacity
        self._data = np.zeros(capacity, dtype=np.float32)
        self._total = 0  # samples ever written
        self._lock = threading.Lock()
        self._grown = threading.Condition(self._lock)

    @property
    def total(self) -> int:
        """How many samples have been written since the start (the end of the stream)."""
        with self._lock:
            return self._total

    def append(self, block: np.ndarray) -> None:
        block = np.asarray(block, dtype=np.float32).ravel()
        skipped = max(0, len(block) - self.capacity)
        block = block[skipped:]
        with self._lock:
            start = (self._total + skipped) % self.capacity
            first = min(len(block), self.capacity - start)
            self._data[start : start + first] = block[:first]
            self._data[: len(block) - first] = block[first:]
            self._total += skipped + len(block)
            self._grown.notify_all()

    def read(self, start: int, stop: int) -> np.ndarray:
        """Samples [start, stop) by absolute index, copied; IndexError if not or no longer held."""
        with self._lock:
            return self._read_locked(start, stop)

    def latest(self, count: int) -> np.ndarray:
        """The last `count` samples (fewer at the very start of a stream)."""
        with self._lock:
            count = min(count, self._total, self.capacity)
            return self._read_locked(self._total - count, self._total)

    def _read_locked(self, start: int, stop: int) -> np.ndarray:
        oldest = max(0, self._total - self.capacity)
        if start > stop or start < oldest or stop > self._total:
            raise IndexError(f"samples [{start}, {stop}) not held (have [{oldest}, {self._total}))")
        if start == stop:
            return np.zeros(0, dtype=np.float32)
        i, j = start % self.capacity, stop % self.capacity
        if i < j:
            return self._data[i:j].copy()
        return np.concatenate([self._data[i:], self._data[:j]])

    def wait_for(self, total: int, timeout: float | None) -> bool:
        """Block until `total` samples have been written; False on timeout."""
        with self._grown:
            return self._grown.wait_for(lambda: self._total >= total, timeout)
