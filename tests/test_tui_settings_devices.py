"""A camera or microphone changed in Settings is used at once, on the real parts: PortAudio
through the virtual microphone, a video file as the camera (issue 22 item 3: they applied only
after a restart, and the status line kept saying `camera ✗` after Save)."""

from __future__ import annotations

from textual.widgets import Input

from servant_core.cli.live import build_run_engine
from servant_core.settings import Settings, save_settings
from servant_tui.app import ServantApp
from servant_tui.main import build_parser
from servant_tui.screens.settings import SettingsScreen
from tests.test_live_path import scene_video
from tests.test_microphone import virtual_mic as virtual_mic  # a fixture
from tests.test_tui_live import settle


def bar(app) -> str:
    return str(app.live.devices.render())


async def test_a_camera_and_microphone_saved_in_settings_open_without_a_restart(
    tmp_path,
    virtual_mic,  # noqa: F811
):
    save_settings(Settings(audio_device="no such microphone", camera=str(tmp_path / "none.avi")))
    video = scene_video("street", tmp_path / "street.avi")
    engine = build_run_engine(build_parser().parse_args(["run"]))
    app = ServantApp(engine, library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: "camera ✗" in bar(app) and "microphone ✗" in bar(app))
        await pilot.press("s")
        await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
        app.screen.query_one("#camera", Input).value = str(video)
        app.screen.query_one("#audio_device", Input).value = ""  # the default input
        await pilot.press("ctrl+s")
        await settle(pilot, lambda: "camera ✓" in bar(app) and "microphone ✓" in bar(app))
        assert engine.take_picture().shape == (240, 320, 3)  # a frame of the video
        assert engine.audio_rate > 0


async def test_a_camera_changed_to_another_that_fails_says_the_new_one(tmp_path):
    """The status line named the old camera (`camera 0: no such camera`) after the user chose
    another that failed too: a fault was said once per device, whatever the device became."""
    save_settings(Settings(camera=str(tmp_path / "none.avi")))
    engine = build_run_engine(build_parser().parse_args(["run", "--no-mic"]))
    app = ServantApp(engine, library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:

        def camera() -> str:
            status = engine.status.get("camera")
            return "" if status is None else status.message

        await settle(pilot, lambda: "none.avi" in camera())
        await pilot.press("s")
        await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
        app.screen.query_one("#camera", Input).value = str(tmp_path / "empty" / "frame_%02d.png")
        await pilot.press("ctrl+s")
        await settle(pilot, lambda: "frame_%02d.png" in camera())
        assert not engine.status["camera"].ok
        assert "camera ✗" in bar(app)
