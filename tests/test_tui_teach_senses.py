"""Teach mode records the motion and ambient windows with the sound, through the real path: an
engine reading the sensor board's emulator on a pty (pyserial) while a paced replay plays the
sound at real speed. The board unplugged mid-recording loses its logs, never the sound."""

from __future__ import annotations

import numpy as np
import pytest
from textual.widgets import Input

from servant_core.capture.replay import Clip, PacedAudio
from servant_core.capture.sample_files import read_samples
from servant_core.capture.sensor_sources import sensor_sources
from servant_core.demo.sensor_emulator import SensorEmulator, script_scene
from servant_core.engine import Engine
from servant_tui.app import ServantApp
from servant_tui.screens.teach import TeachScreen
from tests.test_tui_live import log_text, settle
from tests.tui_library import RATE, noise_recording


@pytest.fixture
def board():
    emulator = SensorEmulator(script_scene([("coffee", 1000.0)]), seed=4)
    port = emulator.start()
    yield emulator, port
    emulator.stop()


async def test_teach_writes_motion_and_ambient_beside_the_sound_and_keeps_the_sound_when_the_board_stops(  # noqa: E501
    tmp_path, board
):
    emulator, port = board
    sources = sensor_sources({"imu": port, "ambient": port})
    sound = PacedAudio([Clip("coffee", noise_recording(60.0, 500.0, seed=3))], RATE)
    engine = Engine(audio=sound, samples={"motion": sources["imu"], "ambient": sources["ambient"]})
    root = tmp_path / "library"
    app = ServantApp(engine, library_root=root)
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: engine.running and engine.audio_rate)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        screen = app.screen
        assert "with its motion and ambient" in str(screen.query_one("#sound Label").render())
        screen.query_one("#new-scene", Input).value = "CoffeeScene"
        await pilot.click("#use-scene")
        await pilot.click("#record")
        await settle(pilot, lambda: screen.windows == 1, tries=1500)

        folder = root / "CoffeeScene"
        (wav,) = folder.glob("*.wav")
        stem = wav.name.removesuffix(".wav")
        assert sorted(p.name for p in folder.iterdir()) == sorted(
            [wav.name, f"{stem}.ambient.csv", f"{stem}.imu.csv"]
        ), "each sense's log beside the sound, under the same name"
        motion = read_samples(folder / f"{stem}.imu.csv", "imu")
        assert abs(len(motion) - 5 * 50) <= 2, "the same 5 s as the sound, at 50 Hz"
        # a still café: gravity alone, about 9.8 m/s²
        assert abs(np.median(np.linalg.norm(motion[:, :3], axis=1)) - 9.8) < 1.0
        ambient = read_samples(folder / f"{stem}.ambient.csv", "ambient")
        assert ambient.shape[1] == 3 and len(ambient) >= 5
        assert not list(folder.glob("*.tmp*")), "written atomically, no temp file left"

        # the board unplugged a second into the next recording
        await pilot.click("#record")
        await pilot.pause(1.0)
        emulator.stop()
        await settle(pilot, lambda: screen.windows == 2, tries=1500)
        assert len(list(folder.glob("*.wav"))) == 2, "the sound is kept"
        assert (
            len(list(folder.glob("*.imu.csv"))) == 1
            and len(list(folder.glob("*.ambient.csv"))) == 1
        )
        await settle(pilot, lambda: "ambient: not recorded" in log_text(app))
        said = [n.message for n in app._notifications]
        lost = [m for m in said if "motion: not recorded" in m]
        assert len(lost) == 1 and "was kept" in lost[0] and "\n" not in lost[0], said
