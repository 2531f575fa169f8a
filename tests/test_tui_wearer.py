"""A wearer's first session in the terminal app, through real parts only, from empty data and
config dirs: the settings name the arm (the project's controller emulator on a pty) and the camera
(an image sequence cv2.VideoCapture reads; the test changes the pictures as the wearer walks);
the microphone is PortAudio's default input, the virtual microphone we play the places into.

Teach two scenes in teach mode (sound, pictures, pose), train the poses, retrain the recognisers,
arm, walk into the second place: the emulator reports the pose taught for it.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from servant_core.cli.live import build_run_engine
from servant_core.demo.scenes import synth_picture
from servant_core.servo.emulator import start_emulator
from servant_core.settings import Settings, default_joints, save_settings
from servant_tui.app import ServantApp
from servant_tui.screens.teach import TeachScreen
from tests.test_live_path import POSES, expected_pulse, scene_sound
from tests.test_microphone import play
from tests.test_microphone import virtual_mic as virtual_mic  # a fixture
from tests.test_tui_live import settle

FRAMES = 3
WINDOWS = 3  # recorded per scene
PICTURES = 4  # taken per scene


def show(scene: str, folder: Path, seed: int) -> None:
    """What the camera sees from now on (each frame replaced atomically)."""
    for k in range(FRAMES):
        ok, png = cv2.imencode(".png", synth_picture(scene, np.random.default_rng([seed, k])))
        assert ok
        tmp = folder / f".frame_{k:02d}.png"
        tmp.write_bytes(png.tobytes())
        os.replace(tmp, folder / f"frame_{k:02d}.png")


async def wait(pilot, predicate, seconds: float) -> None:
    await settle(pilot, predicate, tries=int(seconds / 0.02))


@pytest.mark.timeout(400)
async def test_teach_two_scenes_retrain_arm_and_the_arm_takes_the_taught_pose(
    tmp_path, virtual_mic
):
    emulator, port = start_emulator("maestro")
    camera = tmp_path / "camera"
    camera.mkdir()
    show("coffee", camera, seed=1)
    save_settings(Settings(serial_port=port, camera=str(camera / "frame_%02d.png")))
    sounds = {s: scene_sound(s, tmp_path / f"{s}.wav", seconds=90.0) for s in POSES}
    engine = build_run_engine(None)  # `servant` alone: everything from the settings file
    app = ServantApp(engine)
    player = None
    try:
        async with app.run_test(size=(120, 40)) as pilot:
            await wait(pilot, lambda: app.arm_state is not None and app.arm_state.connected, 20)
            await wait(pilot, lambda: "microphone" in engine.status, 20)
            assert engine.status["microphone"].ok, engine.status["microphone"].message
            await pilot.press("t")
            await wait(pilot, lambda: isinstance(app.screen, TeachScreen), 10)
            teach = app.screen
            for n, scene in enumerate(POSES):
                show(scene, camera, seed=10 + n)
                player = play(sounds[scene])
                teach.query_one("#new-scene").value = scene
                await pilot.click("#use-scene")
                await wait(pilot, lambda scene=scene: teach.scene == scene, 5)
                for k in range(WINDOWS):
                    await pilot.click("#record")
                    await wait(pilot, lambda k=k: teach.windows == k + 1, 30)
                teach.go("pictures")
                for k in range(PICTURES):
                    await pilot.pause(0.3)
                    await pilot.click("#take-picture")
                    await wait(pilot, lambda k=k: teach.pictures == k + 1, 10)
                teach.go("pose")
                await pilot.pause()
                for joint, angle in POSES[scene].items():
                    teach.query_one(f"#joint-{joint}").value = f"{angle:g}"
                await pilot.click("#add-sample")
                await pilot.pause()
                player.kill()
                if n == 0:
                    await pilot.click("#again")
                    await pilot.pause()
            teach.go("train")
            await pilot.pause()
            await pilot.click("#train-learner")
            await wait(pilot, lambda: teach.learner is not None, 60)
            teach.go("train")
            await pilot.pause()
            await pilot.click("#retrain")
            await wait(pilot, lambda: engine.acoustic is not None and engine.visual is not None, 60)
            assert sorted(engine.acoustic.scenes_) == sorted(POSES)
            await pilot.press("escape")
            await pilot.pause()
            await pilot.press("a")
            await wait(pilot, lambda: app.arm_state.armed, 10)

            # The wearer walks out into the street.
            show("street", camera, seed=99)
            player = play(sounds["street"])
            channels = {j.name: j.channel for j in default_joints()}
            street = {j: expected_pulse(j, a) for j, a in POSES["street"].items()}

            def at_street_pose() -> bool:
                return all(
                    abs(emulator.pulse(channels[j]) - pulse) < 8.0 for j, pulse in street.items()
                )

            deadline = time.monotonic() + 60
            while not at_street_pose() and time.monotonic() < deadline:
                await pilot.pause(0.25)
            log = " ".join(line.text for line in app.live.log_view.lines)
            assert at_street_pose(), log[-2000:]
            assert "StreetScene detected" in log
    finally:
        if player is not None:
            player.kill()
        emulator.stop()


@pytest.mark.timeout(120)
@pytest.mark.parametrize("screen", ["t", "s"])
async def test_the_arm_named_by_servant_run_port_stays_attached_after_teach_or_settings(
    tmp_path, screen
):
    """`servant run --port P` with an empty config dir: opening teach mode or the Settings
    screen (both read the user's settings) must not put the settings file's arm (none) in place
    of the one the command line named."""
    from servant_core.cli import build_parser

    emulator, port = start_emulator("maestro")
    args = build_parser().parse_args(["run", "--port", port, "--no-mic", "--no-camera"])
    engine = build_run_engine(args)
    app = ServantApp(engine)
    try:
        async with app.run_test(size=(120, 40)) as pilot:
            await wait(pilot, lambda: app.arm_state is not None and app.arm_state.connected, 20)
            await pilot.press(screen)
            await wait(pilot, lambda: app.screen is not app.live, 10)
            await pilot.pause(1.0)  # the settings reach the engine in a worker
            await pilot.press("escape")
            await wait(pilot, lambda: app.screen is app.live, 10)
            await pilot.pause(1.0)
            assert engine.status["servo"].ok, engine.status["servo"].message
            assert app.arm_state is not None and app.arm_state.connected
    finally:
        engine.stop()
        emulator.stop()
