"""The README's words are the application's (issue 39: step 2 names the first place `cafe`, while
teach mode's name field suggested `e.g. CoffeeScene`, which the log then showed as
`CoffeeSceneScene detected`)."""

from __future__ import annotations

from pathlib import Path

from textual.widgets import Input

from servant_core.fusion.sequential import scene_line
from servant_tui.app import ServantApp
from servant_tui.screens.teach import TeachScreen
from tests.test_tui_live import settle
from tests.tui_replay import ReplayEngine

README = " ".join((Path(__file__).parents[1] / "README.md").read_text().split())


async def test_teach_modes_name_field_suggests_the_readmes_name(tmp_path, monkeypatch):
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    app = ServantApp(ReplayEngine(), library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: app.engine.started.is_set())
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        placeholder = str(app.screen.query_one("#new-scene", Input).placeholder)
    assert placeholder.endswith("e.g. cafe"), placeholder
    assert "Name it (say `cafe`)" in README
    assert f"`{scene_line('cafe')} (81 %)`" in README  # step 5's line for that name
