"""The footer offers only keys that do what it says where the focus is (issue 39 item 15): in
teach mode `q` typed a q into the place's name while the footer said `q Quit`. While the focus
takes typed letters (a text field, or the known places' list, which passes them to the name's
field), the footer offers ctrl+q to quit and f1 for help, and ctrl+q quits; elsewhere `q` and
`?` are offered and do what they say."""

from __future__ import annotations

from textual.widgets import Button, Input

from servant_tui.app import ServantApp
from servant_tui.screens.settings import SettingsScreen
from servant_tui.screens.teach import KnownScenes, TeachScreen
from tests.test_tui_live import settle
from tests.tui_replay import ReplayEngine


def footer(app: ServantApp) -> list[str]:
    """The footer's keys as shown: "q Quit", "^n Next", …"""
    return [f"{key.key_display} {key.description}" for key in app.screen.query("FooterKey")]


async def teach_mode(pilot, app: ServantApp) -> TeachScreen:
    await settle(pilot, lambda: app.engine.started.is_set())
    await pilot.press("t")
    await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
    await pilot.pause()
    return app.screen


def honest_while_typing(keys: list[str]) -> None:
    assert "q Quit" not in keys and "? Help" not in keys, keys
    assert "^q Quit" in keys and "f1 Help" in keys, keys


async def test_typing_a_place_name_at_the_known_places_the_footer_offers_ctrl_q(
    tmp_path, monkeypatch
):
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    app = ServantApp(ReplayEngine(), library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await teach_mode(pilot, app)
        # the replay's places are known: teach mode opens on their list
        assert isinstance(screen.focused, KnownScenes)
        await settle(pilot, lambda: bool(footer(app)))
        honest_while_typing(footer(app))
        await pilot.press("q", "u", "a", "y")
        assert screen.query_one("#new-scene", Input).value == "quay"
        assert app.is_running and app.screen is screen
        honest_while_typing(footer(app))
        await pilot.press("ctrl+q")
        await settle(pilot, lambda: not app.is_running)


async def test_a_text_field_and_a_button_in_teach_mode_and_settings(tmp_path, monkeypatch):
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    app = ServantApp(ReplayEngine(), library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await teach_mode(pilot, app)
        screen.set_focus(screen.query_one("#new-scene", Input))
        await pilot.pause()
        honest_while_typing(footer(app))

        screen.set_focus(screen.query_one("#use-scene", Button))
        await pilot.pause()
        keys = footer(app)
        assert "q Quit" in keys and "? Help" in keys and "^q Quit" not in keys, keys

        await pilot.press("escape", "s")
        await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
        await pilot.pause()
        settings = app.screen
        settings.set_focus(settings.query(Input).first())
        await pilot.pause()
        honest_while_typing(footer(app))
        await pilot.press("q")
        assert app.is_running and app.screen is settings

        settings.set_focus(settings.query(Button).first())
        await pilot.pause()
        assert "q Quit" in footer(app)
        await pilot.press("q")
        await settle(pilot, lambda: not app.is_running)
