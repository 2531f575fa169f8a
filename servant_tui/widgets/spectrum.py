"""The live spectrum pane: log-frequency bars with a dB scale, drawn with eighth blocks.

Rendering is line by line (`render_line`) from strips computed once per frame, so a frame costs a
few numpy operations and one string per row, whatever happens elsewhere on the screen; only the
rows that changed are repainted (the quiet rows above the bars mostly do not), since redrawing
the pane thirty times a second is most of the application's CPU.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from rich.segment import Segment
from rich.style import Style
from textual.geometry import Region
from textual.strip import Strip
from textual.widget import Widget

from servant_core.events import SpectrumFrame

BLOCKS = np.array(list(" ▁▂▃▄▅▆▇█"))
AXIS_WIDTH = 5  # "-60 " and a tick: the dB labels on the left
FREQUENCY_TICKS = (50, 100, 200, 500, 1000, 2000, 5000, 10000, 20000)
# The axis's and the bars' styles, made once rather than for each row of each frame
AXIS_STYLE = Style(color="grey50")
LOUD_STYLE, WARM_STYLE, BAR_STYLE = (
    Style(color="#ff5f5f"),
    Style(color="#ffd75f"),
    Style(color="#5fd787"),
)


def log_band_edges(f_min: float, f_max: float, n_bands: int) -> np.ndarray:
    """`n_bands + 1` edges, equally spaced in log frequency from `f_min` to `f_max`."""
    return np.geomspace(f_min, f_max, n_bands + 1)


def band_levels(freqs: np.ndarray, magnitude_db: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The loudest bin of each band, in dB.

    Low bands can be narrower than the FFT's bin spacing and hold no bin: they take the spectrum
    interpolated at their centre, so the bars stay continuous instead of dropping to silence.
    """
    starts = np.searchsorted(freqs, edges[:-1], side="left")
    stops = np.searchsorted(freqs, edges[1:], side="left")
    centres = np.sqrt(edges[:-1] * edges[1:])
    levels = np.interp(centres, freqs, magnitude_db)
    # Bands are contiguous, so each band holding bins ends where the next such band starts.
    banded = np.flatnonzero(stops > starts)
    if len(banded):
        levels[banded] = np.maximum.reduceat(magnitude_db[: stops[banded[-1]]], starts[banded])
    return levels


def fall(previous: np.ndarray, new: np.ndarray, dt: float, fall_db_per_s: float) -> np.ndarray:
    """Bars rise at once and fall at a fixed rate, like a meter's ballistics."""
    if previous.shape != new.shape:
        return new
    return np.maximum(new, previous - fall_db_per_s * max(dt, 0.0))


def frequency_label(hz: float) -> str:
    return f"{hz / 1000:g}k" if hz >= 1000 else f"{hz:g}"


@lru_cache(maxsize=8)
def axis_line(n_bands: int, f_min: float, f_max: float) -> str:
    """The frequency axis under `n_bands` log-spaced bars: "Hz" and the ticks that fit. Made once
    a width, not at each of the ~25 frames a second."""
    line = [" "] * (AXIS_WIDTH + n_bands)
    line[: AXIS_WIDTH - 1] = list(" Hz ")
    scale = n_bands / np.log(f_max / f_min)
    next_free = AXIS_WIDTH
    for hz in FREQUENCY_TICKS:
        if not f_min <= hz <= f_max:
            continue
        column = AXIS_WIDTH + int(np.log(hz / f_min) * scale)
        text = frequency_label(hz)
        if column < next_free or column + len(text) > len(line):
            continue
        line[column : column + len(text)] = list(text)
        next_free = column + len(text) + 1
    return "".join(line)


class Spectrum(Widget):
    """Live FFT of the microphone: one bar per log-spaced band, 8 levels per character row."""

    DEFAULT_CSS = """
    Spectrum {
        height: 1fr;
        min-height: 4;
    }
    """

    def __init__(
        self,
        *,
        floor_db: float = -80.0,
        ceiling_db: float = 0.0,
        f_min: float = 40.0,
        f_max: float = 16000.0,
        fall_db_per_s: float = 60.0,
        id: str | None = None,
        classes: str | None = None,
    ) -> None:
        super().__init__(id=id, classes=classes)
        self.floor_db = floor_db
        self.ceiling_db = ceiling_db
        self.f_min = f_min
        self.f_max = f_max
        self.fall_db_per_s = fall_db_per_s
        self.frames_shown = 0
        self._levels = np.zeros(0)
        self._last_t: float | None = None
        self._last_frame: SpectrumFrame | None = None
        self._strips: list[Strip] = []
        self._rows_text: list[str] = []  # each strip's text, to repaint only the rows that changed

    @property
    def n_bands(self) -> int:
        return max(self.size.width - AXIS_WIDTH, 1)

    def show_frame(self, frame: SpectrumFrame) -> None:
        if len(frame.freqs) == 0:
            return
        self.frames_shown += 1
        self._apply(frame)

    def _apply(self, frame: SpectrumFrame) -> None:
        edges = log_band_edges(self.f_min, self.f_max, self.n_bands)
        levels = band_levels(np.asarray(frame.freqs), np.asarray(frame.magnitude_db), edges)
        dt = 0.0 if self._last_t is None else frame.t - self._last_t
        self._levels = fall(self._levels, levels, dt, self.fall_db_per_s)
        self._last_t = frame.t
        self._last_frame = frame
        before = self._rows_text
        self._strips = self._draw()
        self._rows_text = [strip.text for strip in self._strips]
        changed = [
            Region(0, y, self.size.width, 1)
            for y, text in enumerate(self._rows_text)
            if y >= len(before) or before[y] != text
        ]
        if len(before) != len(self._rows_text):
            self.refresh()
        elif changed:
            self.refresh(*changed)

    def on_resize(self) -> None:
        if self._last_frame is not None:
            self._levels = np.zeros(0)
            self._last_t = None
            self._apply(self._last_frame)
        else:
            self._strips = self._draw()
            self._rows_text = []

    def _draw(self) -> list[Strip]:
        width, height = self.size.width, self.size.height
        rows = max(height - 1, 1)  # the last row carries the frequency axis
        span = self.ceiling_db - self.floor_db
        if len(self._levels) == self.n_bands:
            fraction = np.clip((self._levels - self.floor_db) / span, 0.0, 1.0)
        else:
            fraction = np.zeros(self.n_bands)
        eighths = np.round(fraction * rows * 8).astype(int)
        from_bottom = np.arange(rows - 1, -1, -1)[:, None]
        cells = np.clip(eighths[None, :] - from_bottom * 8, 0, 8)
        # each row's characters as one string, all rows at once
        bars = np.ascontiguousarray(BLOCKS[cells]).view(f"<U{self.n_bands}")[:, 0]
        strips = []
        for y, text in enumerate(bars.tolist()):
            db = self.ceiling_db - span * y / rows
            label = f"{db:>4.0f}┤" if y % 3 == 0 else "    │"
            segments = [Segment(label, AXIS_STYLE), Segment(text, self._row_style(y, rows))]
            strip = Strip(segments, AXIS_WIDTH + self.n_bands)
            strips.append(strip if AXIS_WIDTH + self.n_bands == width else strip.crop(0, width))
        axis = axis_line(self.n_bands, self.f_min, self.f_max)
        strips.append(Strip([Segment(axis, AXIS_STYLE)]).crop(0, width))
        return strips

    @staticmethod
    def _row_style(y: int, rows: int) -> Style:
        """Green at the bottom, yellow then red near full scale."""
        height = 1.0 - y / max(rows - 1, 1)
        if height > 0.85:
            return LOUD_STYLE
        if height > 0.6:
            return WARM_STYLE
        return BAR_STYLE

    def render_line(self, y: int) -> Strip:
        if y < len(self._strips):
            return self._strips[y]
        return Strip.blank(self.size.width)
