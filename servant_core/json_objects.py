"""JSON objects read from a user's files: each key at most once.

Python's `json` keeps the last of two equal keys, so a settings file holding `"max_angle": 90`
and, lower down, `"max_angle": 400` gave the shoulder 400 without a word; the user edited one
and the other was used. A file with a key twice is refused instead, naming the key.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

SHOWN_CHARS = 40  # of a duplicated key in the message: a file's key may be any length


def unique_keys(pairs: Sequence[tuple[str, Any]]) -> dict[str, Any]:
    """`json.loads`'s `object_pairs_hook`: the object as a dict; ValueError naming the first key
    given twice."""
    found: dict[str, Any] = {}
    for key, value in pairs:
        if key in found:
            shown = key if len(key) <= SHOWN_CHARS else key[:SHOWN_CHARS] + "…"
            raise ValueError(f"the key {shown!r} is given twice in one object; keep one")
        found[key] = value
    return found
