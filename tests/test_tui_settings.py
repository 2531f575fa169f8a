"""The settings screen keeps the user's edits: leaving with unsaved ones asks save, discard or keep
editing. And the command palette names each command once."""

from __future__ import annotations

import json

import pytest
from textual.widgets import Input

from servant_tui.app import ServantApp
from servant_tui.screens.dialogs import UnsavedChanges
from tests.test_tui_live import settle
from tests.tui_replay import ReplayEngine

settings_module = pytest.importorskip("servant_core.settings")


@pytest.fixture
def config(tmp_path, monkeypatch):
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    return tmp_path / "config" / "settings.json"


async def edit_threshold(pilot, app, value: str):
    from servant_tui.screens.settings import SettingsScreen

    await pilot.press("s")
    await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
    screen = app.screen
    screen.query_one("#confidence_threshold", Input).value = value
    await pilot.pause()
    return screen


def app_over(tmp_path) -> ServantApp:
    return ServantApp(ReplayEngine(), library_root=tmp_path, settings=settings_module.Settings())


async def test_escape_with_unsaved_edits_asks_and_keep_editing_keeps_them(tmp_path, config):
    app = app_over(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        screen = await edit_threshold(pilot, app, "75")
        await pilot.press("escape")
        await settle(pilot, lambda: isinstance(app.screen, UnsavedChanges))
        await pilot.click("#keep")
        await settle(pilot, lambda: app.screen is screen)
        assert screen.query_one("#confidence_threshold", Input).value == "75"
        assert not config.exists()


async def test_discard_leaves_without_saving(tmp_path, config):
    app = app_over(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await edit_threshold(pilot, app, "75")
        await pilot.press("escape")
        await settle(pilot, lambda: isinstance(app.screen, UnsavedChanges))
        await pilot.click("#discard")
        await settle(pilot, lambda: app.screen is app.live)
        assert not config.exists()
        assert app.settings.confidence_threshold == 50.0


async def test_save_from_the_question_saves_then_leaves(tmp_path, config):
    app = app_over(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await edit_threshold(pilot, app, "75")
        await pilot.press("escape")
        await settle(pilot, lambda: isinstance(app.screen, UnsavedChanges))
        await pilot.click("#save")
        await settle(pilot, lambda: app.screen is app.live)
        assert json.loads(config.read_text())["confidence_threshold"] == 75.0


async def test_a_save_that_fails_stays_on_the_form(tmp_path, config):
    app = app_over(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        screen = await edit_threshold(pilot, app, "175")  # not a percentage: refused
        await pilot.press("escape")
        await settle(pilot, lambda: isinstance(app.screen, UnsavedChanges))
        await pilot.click("#save")
        await settle(pilot, lambda: app.screen is screen)
        assert any("confidence_threshold" in n.message for n in app._notifications)


async def test_escape_without_edits_just_leaves(tmp_path, config):
    app = app_over(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await edit_threshold(pilot, app, "50")  # typed back as it was: no change
        await pilot.press("escape")
        await settle(pilot, lambda: app.screen is app.live)


async def test_the_command_palette_names_each_command_once(tmp_path):
    app = ServantApp(ReplayEngine(), library_root=tmp_path)
    async with app.run_test(size=(100, 30)):
        titles = [command.title for command in app.get_system_commands(app.screen)]
    assert len(titles) == len(set(titles)), titles
    assert "Help" in titles


async def test_each_joints_channel_and_pulse_widths_are_set_in_settings(tmp_path, config):
    """Issue 22 item 13: README step 1 says to choose each joint's channel; Settings had no
    field for it, nor for the pulse widths its angle limits are sent as."""
    from servant_tui.screens.settings import SettingsScreen

    app = app_over(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
        app.screen.query_one("#elbow-channel", Input).value = "7"
        app.screen.query_one("#elbow-max_pulse_us", Input).value = "2100"
        await pilot.press("ctrl+s")
        await settle(pilot, config.exists)
    saved = settings_module.load_settings(config).joint("elbow")
    assert (saved.channel, saved.max_pulse_us) == (7, 2100.0)


async def test_a_channel_that_is_not_a_whole_number_is_one_line(tmp_path, config):
    from servant_tui.screens.settings import SettingsScreen

    app = app_over(tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.press("s")
        await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
        app.screen.query_one("#elbow-channel", Input).value = "1.5"
        await pilot.press("ctrl+s")
        await settle(pilot, lambda: app._notifications)
        assert "elbow channel: '1.5' is not a whole number" in list(app._notifications)[0].message
    assert not config.exists()


async def test_the_form_opens_on_the_audio_input_so_typing_goes_into_it(tmp_path, config):
    """README step 1 goes through the fields in order; the scroll view had the focus, and what
    a newcomer typed first went nowhere."""
    from servant_tui.screens.settings import SettingsScreen

    app = app_over(tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("s")
        await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
        await pilot.press(*"pulse", "tab", *"cam.avi")
        assert app.screen.query_one("#audio_device", Input).value == "pulse"
        assert app.screen.query_one("#camera", Input).value == "cam.avi"
