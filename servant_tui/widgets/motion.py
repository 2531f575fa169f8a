"""The motion pane: the wearer's acceleration over the last seconds as a trace, and a line with
what the sample senses (motion, ambient) make of the place and the light, warmth and pressure.

The trace is drawn like the spectrum: strips computed once per sensor frame (a few a second),
each column the mean |a| of its stretch of the last `TRACE_SECONDS`, in eighth blocks.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from rich.segment import Segment
from rich.style import Style
from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Vertical
from textual.strip import Strip
from textual.widget import Widget
from textual.widgets import Static

from servant_core.event_text import confidence_text, place
from servant_core.events import DeviceStatus, SensePrediction, SensorFrame
from servant_core.senses import SAMPLE_SENSES
from servant_tui.widgets.spectrum import BLOCKS

TRACE_SECONDS = 10.0
G = 9.80665
# Full scale of the trace: sitting still (gravity alone) fills half of it, walking wiggles about
# the middle and a bounce in the gym reaches the top.
TRACE_TOP = 2 * G
AXIS_WIDTH = 4  # "20┤": the scale on the left
NO_MOTION = "no motion sensor (start with --imu PORT or a log)"
# The ambient channels as the line shows them: (channel, format)
AMBIENT_UNITS = (("lux", "{:.0f} lx"), ("celsius", "{:.1f} °C"), ("hpa", "{:.0f} hPa"))


def acceleration_magnitude(rows: np.ndarray, channels: Sequence[str]) -> np.ndarray:
    """|a| of each reading in m/s², from the ax, ay, az columns (the first three if unnamed)."""
    rows = np.asarray(rows, dtype=np.float64).reshape(len(rows), -1)
    names = list(channels)
    axes = [names.index(a) for a in ("ax", "ay", "az")] if {"ax", "ay", "az"} <= set(names) else []
    return np.sqrt((rows[:, axes or [0, 1, 2]] ** 2).sum(axis=1))


def column_means(values: np.ndarray, n_columns: int, span: int) -> np.ndarray:
    """The mean of the readings in each of `n_columns` equal stretches of the last `span` readings
    (`values`, newest last). A stretch before the first reading is NaN: a trace that has just
    begun grows from the right, at the same scale in time as a full one."""
    values = np.asarray(values, dtype=np.float64)[-span:]
    start = span - len(values)  # where the readings begin within the span
    columns = np.arange(n_columns)
    lo = columns * span // n_columns
    hi = np.maximum((columns + 1) * span // n_columns, lo + 1)  # more columns than readings
    lo = np.clip(lo - start, 0, len(values))
    hi = np.clip(hi - start, 0, len(values))
    sums = np.concatenate(([0.0], np.cumsum(values)))
    means = np.full(n_columns, np.nan)
    has = hi > lo
    means[has] = (sums[hi[has]] - sums[lo[has]]) / (hi[has] - lo[has])
    return means


def block_rows(fractions: np.ndarray, n_rows: int) -> list[str]:
    """An area chart `n_rows` cells high in eighth blocks, top row first; NaN draws nothing."""
    fractions = np.nan_to_num(np.clip(fractions, 0.0, 1.0), nan=0.0)
    eighths = np.round(fractions * n_rows * 8).astype(int)
    return ["".join(BLOCKS[np.clip(eighths - (n_rows - 1 - y) * 8, 0, 8)]) for y in range(n_rows)]


class MotionTrace(Widget):
    """|a| over the last `TRACE_SECONDS`, newest on the right, 0 to `TRACE_TOP` m/s²."""

    DEFAULT_CSS = """
    MotionTrace { height: 1fr; min-height: 1; }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.frames_shown = 0
        self._frame: SensorFrame | None = None
        self._strips: list[Strip] = []

    def show_frame(self, frame: SensorFrame) -> None:
        self.frames_shown += 1
        self._frame = frame
        self._strips = self._draw()
        self.refresh()

    def on_resize(self) -> None:
        # a frame that came before the first layout was drawn at no width: draw it again now
        self._strips = self._draw()
        self.refresh()

    def _draw(self) -> list[Strip]:
        width, rows = self.size.width, max(self.size.height, 1)
        columns = max(width - AXIS_WIDTH, 1)
        frame = self._frame
        if frame is None or not len(frame.rows):
            fractions = np.full(columns, np.nan)
        else:
            magnitude = acceleration_magnitude(frame.rows, frame.channels)
            span = max(int(round(frame.rate * TRACE_SECONDS)), 1)
            fractions = column_means(magnitude, columns, span) / TRACE_TOP
        axis_style, trace_style = Style(color="grey50"), Style(color="#5fafff")
        strips = []
        for y, cells in enumerate(block_rows(fractions, rows)):
            if y == 0:
                label = f"{TRACE_TOP:3.0f}┤"
            elif y == rows - 1:
                label = "  0┤"
            else:
                label = "   │"
            strips.append(
                Strip([Segment(label, axis_style), Segment(cells, trace_style)]).crop(0, width)
            )
        return strips

    def render_line(self, y: int) -> Strip:
        if y < len(self._strips):
            return self._strips[y]
        return Strip.blank(self.size.width)


class MotionPane(Vertical):
    """The trace under two lines: each sample sense's latest judgement, then the ambient values
    and any sensor that stopped. `senses`: the sample senses the engine reads; without motion
    the trace gives way to a line saying how to start one."""

    DEFAULT_CSS = """
    MotionPane { height: 8; }
    MotionPane.-no-motion { height: auto; }
    MotionPane > Static { height: auto; }
    """

    def __init__(self, senses: Sequence[str] = (), *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.senses = [s for s in SAMPLE_SENSES if s in senses]
        self.predictions: dict[str, SensePrediction] = {}
        self.problems: dict[str, str] = {}  # device → why it does not read
        self.ambient: dict[str, float] = {}
        self.said = Static(id="motion-said")
        self.values = Static(id="motion-values")
        self.trace = MotionTrace(id="motion-trace")
        self.trace.display = "motion" in self.senses
        self.set_class("motion" not in self.senses, "-no-motion")

    def compose(self) -> ComposeResult:
        yield self.said
        yield self.values
        yield self.trace

    def on_mount(self) -> None:
        self.said.update(self._said_text())
        self._show_values()

    def show_frame(self, frame: SensorFrame) -> None:
        if frame.sense == "motion":
            self.trace.show_frame(frame)
        elif frame.sense == "ambient" and len(frame.rows):
            latest = np.asarray(frame.rows)[-1]
            self.ambient = {c: float(v) for c, v in zip(frame.channels, latest, strict=False)}
            self._show_values()

    def show_prediction(self, prediction: SensePrediction) -> None:
        self.predictions[prediction.sense] = prediction
        self.said.update(self._said_text())

    def show_status(self, status: DeviceStatus) -> None:
        """A sample sense's device (imu, ambient) stopped reading, or reads again."""
        if status.ok:
            self.problems.pop(status.device, None)
        else:
            self.problems[status.device] = status.message
        self._show_values()

    def _said_text(self) -> Text:
        parts: list[Text] = []
        if "motion" not in self.senses:
            parts.append(Text(NO_MOTION, "grey50"))
        for sense in self.senses:
            said = self.predictions.get(sense)
            if said is None:
                parts.append(Text.assemble((f"{sense} ", "bold"), ("–", "grey50")))
                continue
            # the spaces end the styled runs (see ServantApp.log_line)
            line = Text.assemble((f"{sense} ", "bold"), (place(said.scene), "cyan"))
            if said.scene:  # a confidence in no scene says nothing
                line.append(f" {confidence_text(said.confidence, said.confidence_unit)}")
            parts.append(line)
        return Text(" · ").join(parts)

    def _show_values(self) -> None:
        """The light, warmth and pressure last read, and why a sensor does not read; nothing
        (no line) when there is neither."""
        parts = [form.format(self.ambient[c]) for c, form in AMBIENT_UNITS if c in self.ambient]
        line = Text(" ".join(parts))
        for message in self.problems.values():
            line.append_text(Text.assemble(" · " if len(line) else "", (message, "red")))
        self.values.update(line)
        self.values.display = bool(len(line))
