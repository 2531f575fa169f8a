"""The Library's status line says where a retrain saved the model, whole (issue 39 item 15):
at 120x40 `R` cut the path, one line with "sound and pictures retrained on" and the places."""

from __future__ import annotations

from pathlib import Path

import pytest
from textual.geometry import Region

from servant_tui.app import ServantApp
from servant_tui.screens.library import LibraryScreen
from tests.test_tui_live import settle
from tests.tui_library import RATE, noise_recording
from tests.tui_replay import ReplayEngine

HOME = Path("/home/newcomer")
MODEL = HOME / ".local/share/servant/model.npz"  # where `servant` keeps it (platformdirs)
# given with --model, outside the home folder: said whole, on a line of its own if need be
ELSEWHERE = Path("/srv/servant/wearers/newcomer/models/2024-06-01-after-teach-mode/model.npz")


def shown(widget) -> str:
    """What the widget shows on the screen, its rows joined by newlines."""
    lines = widget.render_lines(Region(0, 0, widget.size.width, widget.size.height))
    return "\n".join(line.text.rstrip() for line in lines)


@pytest.mark.parametrize(
    ("model", "said"),
    [(MODEL, "~/.local/share/servant/model.npz"), (ELSEWHERE, str(ELSEWHERE))],
    ids=["home", "elsewhere"],
)
async def test_retrain_at_120x40_shows_the_saved_models_whole_path(
    model, said, tmp_path, monkeypatch
):
    from servant_core.audio import write_wav

    monkeypatch.setenv("HOME", str(HOME))
    root = tmp_path / "library"
    for i, scene in enumerate(("CafeScene", "ConstructionScene", "StreetScene")):
        write_wav(root / scene / "teach-1.wav", noise_recording(5.0, 500.0 * (i + 1), i), RATE)
    engine = ReplayEngine()
    engine.model_path = model
    app = ServantApp(engine, library_root=root)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("l")
        await settle(pilot, lambda: isinstance(app.screen, LibraryScreen))
        await pilot.press("R")
        status = app.screen.query_one("#library-status")
        await settle(pilot, lambda: "model saved" in str(status.render()))
        await pilot.pause()
        text = shown(status)
        assert "retrained on CafeScene, ConstructionScene, StreetScene" in text, text
        assert said in text, text
