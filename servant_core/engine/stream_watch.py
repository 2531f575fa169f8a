"""Watching a live sample stream (a sensor board): it stalls, sends only junk, or runs at a rate
other than the one its windows are cut by.

`StreamWatch` turns both into news for the device's status line: a stall after `STALL_SECONDS`
without a reading, and a rate off by more than `RATE_FACTOR` either way over `PERIOD_SECONDS`
(after `WARM_UP_SECONDS`). While the rate is off, the readings are not used. The watch is pure
bookkeeping on the times it is given.
"""

from __future__ import annotations

from dataclasses import dataclass

STALL_SECONDS = 3.0
WARM_UP_SECONDS = 0.5
PERIOD_SECONDS = 3.0
RATE_FACTOR = 2.0


@dataclass
class News:
    """A change to say on the status line: the stream is `ok` again, or what is wrong."""

    ok: bool
    message: str


class StreamWatch:
    """The health of one live stream of `rate` readings a second named `name`, opened at
    `opened_at` (the engine's clock). `arrived` and `quiet` return `News` on a change only."""

    def __init__(self, name: str, rate: float, opened_at: float) -> None:
        self.name = name
        self.rate = float(rate)
        self.last_rows_at = opened_at
        self.period_start = opened_at + WARM_UP_SECONDS
        self.period_rows = 0
        self.stalled = False
        self.off_rate: float | None = None  # the rate measured while it is off, else None

    @property
    def usable(self) -> bool:
        """Whether readings may be cut into windows now (the rate is the one expected)."""
        return self.off_rate is None

    def arrived(self, t: float, rows: int) -> News | None:
        """`rows` readings came at `t`."""
        news = None
        self.last_rows_at = t
        if self.stalled:  # the rate is measured afresh from here
            self.stalled = False
            self.period_start, self.period_rows = t, 0
            news = self._fine() if self.usable else None  # still off: said when it is not
        if t < self.period_start:
            return news
        self.period_rows += rows
        span = t - self.period_start
        # a flood is plain before the stretch ends: its readings are not used a moment longer
        flooding = self.period_rows > RATE_FACTOR * self.rate * PERIOD_SECONDS
        if span < PERIOD_SECONDS and not (flooding and self.usable):
            return news
        measured = self.period_rows / max(span, 1.0 / self.rate)
        self.period_start, self.period_rows = t, 0
        off = not (self.rate / RATE_FACTOR <= measured <= self.rate * RATE_FACTOR)
        if off and self.off_rate is None:
            self.off_rate = measured
            return News(
                False,
                f"{self.name}: {measured:.0f} readings a second arrive where {self.rate:g} are "
                f"expected; set the board's rate to {self.rate:g} a second (docs/sensors.md); "
                "its readings are not used until then",
            )
        if not off and self.off_rate is not None:
            self.off_rate = None
            return self._fine()
        return news

    def quiet(self, t: float, junk_lines: int = 0) -> News | None:
        """No reading came by `t`; `junk_lines`: lines the source skipped since it opened."""
        if self.stalled or t - self.last_rows_at < STALL_SECONDS:
            return None
        self.stalled = True
        waited = f"no reading for {t - self.last_rows_at:.0f} s"
        if junk_lines:
            return News(
                False,
                f"{self.name}: {waited}, only {junk_lines} lines that are not readings; check "
                "the baud rate and that the board runs docs/sensor_board.ino",
            )
        return News(False, f"{self.name}: {waited}; is the board powered and its sketch running?")

    def _fine(self) -> News:
        return News(True, f"{self.name}: reading at {self.rate:g} Hz")
