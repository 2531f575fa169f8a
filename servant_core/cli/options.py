"""Reusable argparse `type=` validators: a bad option value is refused by the parser, in one line.

argparse turns the `argparse.ArgumentTypeError` raised here into
`servant <command>: error: argument --window: <message>` and exit status 2, before any work starts.
`nan` and `inf` parse as floats in Python; every validator here refuses them.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from servant_core.choices import MAX_RATE, MAX_WINDOW_SECONDS, MIN_RATE, MIN_WINDOW_SECONDS


def finite_float(low: float, high: float) -> Callable[[str], float]:
    """A float in [low, high]; nan and inf are refused."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        if not math.isfinite(value) or not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text!r} is not between {low:g} and {high:g}")
        return value

    parse.__name__ = "number"  # argparse names the type in its own messages
    return parse


def open_fraction(text: str) -> float:
    """A float strictly between 0 and 1 (a share of the files)."""
    value = finite_float(0.0, 1.0)(text)
    if value in (0.0, 1.0):
        raise argparse.ArgumentTypeError(f"{text!r} is not strictly between 0 and 1")
    return value


def bounded_int(low: int, high: int) -> Callable[[str], int]:
    """An integer in [low, high] ("44100", not "44100.0" nor "1e8")."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"{text!r} is not between {low} and {high}")
        return value

    parse.__name__ = "whole number"
    return parse


sample_rate = bounded_int(MIN_RATE, MAX_RATE)
"""A sample rate in Hz, within what the audio files and microphones Servant reads can carry."""

window_seconds = finite_float(MIN_WINDOW_SECONDS, MAX_WINDOW_SECONDS)
"""The length of the audio window a recogniser judges, in seconds."""

# The fusion windows are seconds of engine time, stepped through half a second at a time when
# evaluating: ten minutes is far beyond any use (the paper's are 30 s and 20 s) and keeps that fast.
fusion_seconds = finite_float(0.0, 600.0)

picture_count = bounded_int(1, 1000)
"""How many pictures must confirm a scene."""
