"""Settings' Save and the armed arm, in the application on the servo emulator (issue 39 item 16:
Save with the port unchanged left the arm ARMED while README step 1 said Save connects it
disarmed). What the README says now, done through the keys it names: a Save that leaves the
port, the controller and the joints as they were leaves the arm as it was; one that changes any
of them connects it afresh, disarmed."""

from __future__ import annotations

from pathlib import Path

from textual.widgets import Input

from servant_core.cli.live import build_run_engine
from servant_core.settings import Settings, save_settings
from servant_tui.app import ServantApp
from servant_tui.main import build_parser
from servant_tui.screens.settings import SettingsScreen
from tests.test_live_path import emulator as emulator  # a fixture
from tests.test_tui_live import settle


async def save(pilot, app: ServantApp, field: str, value: str) -> None:
    """`s`, one field changed, Ctrl-S, escape: as the README's step 1 has it."""
    await pilot.press("s")
    await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
    app.screen.query_one(f"#{field}", Input).value = value
    await pilot.press("ctrl+s")
    await settle(pilot, lambda: app.screen.saved_form == app.screen.form())
    await app.workers.wait_for_complete()  # the engine has taken the settings
    await pilot.press("escape")
    await settle(pilot, lambda: not isinstance(app.screen, SettingsScreen))
    await pilot.pause()


async def test_save_keeps_the_arm_armed_unless_the_arm_changed(
    tmp_path,
    emulator,  # noqa: F811
):
    _, port = emulator
    save_settings(Settings(serial_port=port))
    engine = build_run_engine(build_parser().parse_args(["run", "--no-mic", "--no-camera"]))
    app = ServantApp(engine, library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: app.arm_state is not None and app.arm_state.connected)
        await pilot.press("a")
        await settle(pilot, lambda: app.arm_state.armed)

        await save(pilot, app, "confidence_threshold", "70")
        assert engine.confidence_threshold == 70.0
        assert engine.link is not None and engine.link.armed
        assert app.arm_state.armed and "ARMED" in app.live.arm.border_title

        await save(pilot, app, "shoulder-max_speed_deg_s", "10")
        # closed and opened afresh on the emulator's pty: under the whole suite on two cores
        # that took over 15 s once (each probe of the controller waits up to 0.5 s)
        await settle(pilot, lambda: not app.arm_state.armed and app.arm_state.connected, tries=2000)
        assert engine.link is not None and not engine.link.armed
        assert "ARMED" not in app.live.arm.border_title
    readme = " ".join((Path(__file__).parents[1] / "README.md").read_text().split())
    assert "Save: Servant connects the arm at once, **disarmed**" in readme
    assert "controller and joints as they were leaves the arm as it was" in readme
