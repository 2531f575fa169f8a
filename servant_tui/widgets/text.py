"""Small text pieces the panes share: engine times and horizontal bars."""

from __future__ import annotations

from pathlib import Path

from rich.text import Text

from servant_core.errors import ServantError


def clock(t: float) -> str:
    """Engine time as minutes:seconds since the engine started, to a tenth of a second."""
    # Rounded to tenths before the split: rounding the seconds after it showed 59.96 s as 00:60.0.
    minutes, tenths = divmod(round(max(t, 0.0) * 10), 600)
    return f"{minutes:02d}:{tenths / 10:04.1f}"


def bar(fraction: float, width: int, style: str = "green") -> Text:
    """A bar `width` cells long filled to `fraction` (clipped to 0..1), in eighths of a cell."""
    fraction = min(max(fraction, 0.0), 1.0)
    eighths = round(fraction * width * 8)
    full, rest = divmod(eighths, 8)
    partial = " ▏▎▍▌▋▊▉"[rest] if full < width else ""
    filled = "█" * full + partial.strip()
    return Text.assemble((filled, style), ("·" * (width - len(filled)), "grey35"))


def path_text(path: Path) -> str:
    """A path as the user reads it, their home folder as ~ (what a shell would accept)."""
    try:
        return f"~/{path.relative_to(Path.home())}"
    except (ValueError, RuntimeError):  # elsewhere, or no home to be found
        return str(path)


def error_text(error: BaseException) -> str:
    """An error as the user reads it: a ServantError is already one clear line; anything else
    is unexpected, so its type is kept."""
    return str(error) if isinstance(error, ServantError) else f"{type(error).__name__}: {error}"
