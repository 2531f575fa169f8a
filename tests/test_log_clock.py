"""The log's clock (issue 39 item 8): minutes and seconds since the engine started, the seconds
rounded to a tenth before they are split from the minutes, so 59.96 s never reads `00:60.0`."""

from __future__ import annotations

import pytest

from servant_tui.widgets.text import clock


@pytest.mark.parametrize(
    ("t", "shown"),
    [
        (0.0, "00:00.0"),
        (5.04, "00:05.0"),
        (59.94, "00:59.9"),
        (59.96, "01:00.0"),  # was 00:60.0
        (1139.96, "19:00.0"),  # was 18:60.0
        (1559.98, "26:00.0"),  # was 25:60.0
        (1145.0, "19:05.0"),
        (-0.3, "00:00.0"),  # a clock read just before the engine's start
    ],
)
def test_the_log_clock_rounds_before_it_splits_minutes_from_seconds(t, shown):
    assert clock(t) == shown


def test_every_tenth_of_the_first_hour_reads_as_a_real_time():
    for tenth in range(36000):
        minutes, seconds = clock(tenth / 10 - 0.04).split(":")
        assert float(seconds) < 60.0 and int(minutes) * 600 + round(float(seconds) * 10) == tenth
