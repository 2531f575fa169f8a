"""The colours pane: the current frame's dominant colours with their shares, beside the training
palette they matched."""

from __future__ import annotations

import numpy as np
from rich.color import Color
from rich.console import Group
from rich.style import Style
from rich.table import Table
from rich.text import Text
from textual.widgets import Static

from servant_core.events import Palette

# Swatches are drawn in 16 levels a channel (4,096 colours), and with styles built here, not parsed
# from markup. Each distinct style is kept in process-wide caches of Rich and Textual (parsing,
# combining, filtering, ANSI codes; 1,024 to 4,096 entries each); a camera gives three colours
# never seen before with every picture, so exact colours filled those caches for most of an hour
# (~+8 MB/h in `bench/soak.py`). The demo's pictures now come in a couple of hundred swatch colours.
LEVEL = 17  # 255 / 15


def swatch_colour(rgb: np.ndarray) -> Color:
    """The colour a swatch is drawn in: each channel rounded to the nearest of 16 levels."""
    r, g, b = (int(round(int(v) / LEVEL)) * LEVEL for v in rgb)
    return Color.from_rgb(r, g, b)


def swatch(rgb: np.ndarray, width: int = 4) -> Text:
    return Text(" " * width, style=Style(bgcolor=swatch_colour(rgb)))


def hex_colour(rgb: np.ndarray) -> str:
    return "#{:02x}{:02x}{:02x}".format(*(int(v) for v in rgb))


def share_strip(colours: np.ndarray, shares: np.ndarray, width: int) -> Text:
    """One line `width` cells long, each colour taking cells in proportion to its share."""
    cells = np.floor(np.cumsum(shares) / max(float(np.sum(shares)), 1e-9) * width + 0.5).astype(int)
    text = Text()
    start = 0
    for rgb, stop in zip(colours, cells, strict=True):
        text.append_text(swatch(rgb, int(stop) - start))
        start = int(stop)
    return text


class ColoursPane(Static):
    DEFAULT_CSS = """
    ColoursPane { height: 1fr; }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__("waiting for the camera…", id=id)
        self.palette: Palette | None = None

    def show_palette(self, palette: Palette) -> None:
        self.palette = palette
        self.update(self._render_palette(palette), layout=False)

    def on_resize(self) -> None:
        if self.palette is not None:
            self.update(self._render_palette(self.palette), layout=False)

    def _render_palette(self, palette: Palette) -> Group:
        table = Table.grid(padding=(0, 1))
        table.add_column()
        table.add_column(justify="right")
        table.add_column()
        table.add_column()
        matched: np.ndarray | list[np.ndarray] = (
            palette.matched_colours if palette.matched_colours is not None else []
        )
        table.add_row(
            Text("seen", style="bold"), "", "", Text(palette.matched_scene or "no match", "bold")
        )
        for i, (rgb, share) in enumerate(zip(palette.colours, palette.shares, strict=True)):
            trained = swatch(matched[i]) if i < len(matched) else Text("")
            table.add_row(swatch(rgb), f"{100 * share:3.0f}%", hex_colour(rgb), trained)
        width = max(self.size.width - 2, 8)
        return Group(share_strip(palette.colours, palette.shares, width), table)
