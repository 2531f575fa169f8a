"""Fuzzing option values (issue 13 item 7): whatever text an option is given, the parser
accepts it or refuses it in one line with exit status 2, before any work starts; no traceback,
no hang (`--acoustic-window inf` once hung `eval fusion`, `--window 0` raised ZeroDivisionError).

About 2,000 cases a run, each a parse through `servant_core.cli.main` in-process (~10 ms).
"""

from __future__ import annotations

import math
import os
from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.cli_harness import assert_clear, run_cli

SCALE = float(os.environ.get("SERVANT_FUZZ_SCALE", "1"))
MISSING = "/nonexistent/servant-fuzz-library"

# (command before the option, option, what a valid value is)
NUMBER_OPTIONS = [
    (["train", MISSING], "--window", lambda v: 0.5 <= v <= 60),
    (["train", MISSING], "--rate", lambda v: v == int(v) and 8000 <= v <= 192000),
    (["eval", "audio", MISSING], "--window", lambda v: 0.5 <= v <= 60),
    (["eval", "audio", MISSING], "--rate", lambda v: v == int(v) and 8000 <= v <= 192000),
    (["eval", "fusion", MISSING], "--acoustic-window", lambda v: 0 <= v <= 600),
    (["eval", "fusion", MISSING], "--confirm-window", lambda v: 0 <= v <= 600),
    (["eval", "fusion", MISSING], "--pictures", lambda v: v == int(v) and 1 <= v <= 1000),
    (["eval", "image", MISSING], "--split", lambda v: 0 < v < 1),
    (["predict", MISSING, "--image", "x.png"], "--acoustic-window", lambda v: 0 <= v <= 600),
    (["predict", MISSING, "--image", "x.png"], "--pictures", lambda v: v == int(v) and 1 <= v),
]

values = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**12), 10**12).map(str),
    st.sampled_from(["nan", "inf", "-inf", "NaN", "Infinity", "1e400", "0x10", "1_000", "", " 5"]),
    st.text(max_size=12),
)


def fuzz(examples: int) -> Any:
    return settings(
        max_examples=max(1, int(examples * SCALE)),
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
    )


def as_number(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


@fuzz(1800)
@given(case=st.sampled_from(NUMBER_OPTIONS), value=values)
def test_fuzz_number_options(case, value: str) -> None:
    before, option, valid = case
    outcome = run_cli(*before, f"{option}={value}")
    assert_clear(outcome, seconds=10)
    assert outcome.code == 2  # the library does not exist: refused either way, in one line
    number = as_number(value)
    if number is not None and valid(number) and "argument" in outcome.err:
        # a valid value may only be refused for its form ("5.0" where a whole number is due)
        assert option in ("--rate", "--pictures") or value.strip() != value, outcome.err
    if number is None or not valid(number):
        assert f"argument {option}" in outcome.err, outcome.err


@fuzz(200)
@given(
    words=st.lists(
        st.sampled_from(["--method", "--audio-method", "--image-method", "--x", "-o"])
        | st.text(max_size=6),
        max_size=4,
    )
)
def test_fuzz_stray_arguments(words: list[str]) -> None:
    outcome = run_cli("train", MISSING, *words)
    assert_clear(outcome, seconds=10)
