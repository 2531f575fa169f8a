"""Numbers read from files (JSON, CSV, a sensor's line), checked as numbers before conversion.

Python's integers have no bound: a 400-digit JSON number parses, and then `math.isfinite` or
`float()` on it raises `OverflowError` far from where it was read. An integer is therefore
compared with the float range first (comparing an int with a float is exact and never
overflows), and only then converted.
"""

from __future__ import annotations

import json
import math
import sys
from typing import Any

FLOAT_MAX = sys.float_info.max
# A time stamp in the widest unit a file or a board uses (nanoseconds) fits in 64 bits.
MAX_STAMP = 2**63


def is_finite_number(value: object) -> bool:
    """An int or float that is a finite float: not a bool (JSON's `true` is no number), not
    NaN nor infinity, and not an integer beyond the float range."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    if isinstance(value, int):
        return -FLOAT_MAX <= value <= FLOAT_MAX
    return math.isfinite(value)


def bounded_int(text: str) -> int:
    """`int(text)` for a number read from a file; ValueError beyond the float range (and, as
    Python's own limit, beyond 4300 digits)."""
    value = int(text)
    if not -FLOAT_MAX <= value <= FLOAT_MAX:
        raise ValueError(f"the number {text[:12]}... ({len(text)} digits) is too large")
    return value


def json_loads(text: str | bytes, **options: Any) -> Any:
    """`json.loads` with every integer checked by `bounded_int`: a file's huge integer is a
    ValueError where the file is read, not an OverflowError where it is used."""
    return json.loads(text, parse_int=bounded_int, **options)
