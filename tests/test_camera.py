"""The camera through cv2.VideoCapture, on a video file and an image sequence the tests write."""

from __future__ import annotations

import os
import subprocess
import sys

import cv2
import numpy as np
import pytest

from servant_core.capture.camera import Camera, parse_camera
from servant_core.capture.replay import Clip, PacedAudio
from servant_core.capture.source import ManualClock
from servant_core.engine import Engine
from servant_core.errors import ServantError
from servant_core.events import DeviceStatus, Palette
from servant_core.fusion import FusionConfig, SequentialFusion

# BGR: red, green, blue, then yellow
COLOURS = [(0, 0, 255), (0, 255, 0), (255, 0, 0), (0, 255, 255)]
SIZE = (64, 48)


def write_video(path, fourcc: str, frames_per_colour: int = 3) -> None:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 10.0, SIZE)
    assert writer.isOpened(), f"OpenCV cannot write {fourcc} here"
    for colour in COLOURS:
        for _ in range(frames_per_colour):
            writer.write(np.full((SIZE[1], SIZE[0], 3), colour, np.uint8))
    writer.release()


def mean_colour(frame: np.ndarray) -> np.ndarray:
    return frame.reshape(-1, 3).mean(axis=0)


@pytest.mark.parametrize(("fourcc", "suffix"), [("mp4v", ".mp4"), ("MJPG", ".avi")])
def test_reads_a_video_file_as_a_camera_and_starts_again_at_its_end(tmp_path, fourcc, suffix):
    path = tmp_path / f"camera{suffix}"
    write_video(path, fourcc)
    camera = Camera(str(path))
    camera.open()
    frames = [camera.read() for _ in range(2 * len(COLOURS) * 3)]
    camera.close()
    assert all(f.shape == (SIZE[1], SIZE[0], 3) and f.dtype == np.uint8 for f in frames)
    seen = [mean_colour(f) for f in frames]
    expected = [np.array(c, float) for c in COLOURS for _ in range(3)] * 2  # looped once
    for got, want in zip(seen, expected, strict=True):
        assert np.abs(got - want).max() < 30, (got, want)


def test_image_sequence_pattern_and_device_index_parsing(tmp_path):
    for i, colour in enumerate(COLOURS):
        cv2.imwrite(
            str(tmp_path / f"img_{i:03d}.png"), np.full((SIZE[1], SIZE[0], 3), colour, np.uint8)
        )
    camera = Camera(str(tmp_path / "img_%03d.png"))
    got = [mean_colour(camera.read()) for _ in COLOURS]
    camera.close()
    assert np.allclose(got, np.array(COLOURS, float))
    assert parse_camera("0") == 0 and parse_camera(" 2 ") == 2
    assert parse_camera("clip.mp4") == "clip.mp4"


def test_a_missing_camera_or_file_is_one_clear_error(tmp_path):
    with pytest.raises(ServantError, match="cannot open this video"):
        Camera(str(tmp_path / "nothing.mp4")).open()
    with pytest.raises(ServantError, match="no such camera"):
        Camera(57).open()  # no camera here; /dev/video57 does not exist anywhere sensible


def test_a_camera_that_fails_mid_run_is_reported_once_and_reopened(tmp_path):
    """The image sequence disappears mid-run (a camera unplugged), then comes back."""
    paths = [tmp_path / f"img_{i:03d}.png" for i in range(2)]
    for path, colour in zip(paths, COLOURS, strict=False):
        cv2.imwrite(str(path), np.full((SIZE[1], SIZE[0], 3), colour, np.uint8))
    clock = ManualClock()
    # Silence only drives the clock.
    silence = PacedAudio(
        [Clip(None, np.zeros(8000 * 60, np.float32))], 8000, realtime=False, clock=clock
    )
    # A fusion policy that always wants a picture: a window is kept open by a first sound.
    fusion = SequentialFusion(FusionConfig(acoustic_window_s=1e9, picture_interval_s=0.5))
    fusion.on_acoustic("somewhere", 50.0, 0.0)
    engine = Engine(
        audio=silence,
        camera=Camera(str(tmp_path / "img_%03d.png")),
        fusion=fusion,
        clock=clock,
        reopen_seconds=1.0,
    )
    events: list = []
    engine.subscribe(events.append)
    engine.run_until(5.0)
    for path in paths:
        path.unlink()
    engine.run_until(15.0)
    for path, colour in zip(paths, COLOURS, strict=False):
        cv2.imwrite(str(path), np.full((SIZE[1], SIZE[0], 3), colour, np.uint8))
    engine.run_until(25.0)
    engine.stop()

    camera = [e for e in events if isinstance(e, DeviceStatus) and e.device == "camera"]
    assert [s.ok for s in camera] == [True, False, True], camera
    assert "no frame" in camera[1].message or "cannot open" in camera[1].message
    palettes = [e.t for e in events if isinstance(e, Palette)]
    assert any(t < 5 for t in palettes) and any(t > 16 for t in palettes)
    assert not any(6 < t < 15 for t in palettes)  # no picture while it was gone


def test_an_image_sequence_that_cannot_be_opened_writes_nothing_to_the_terminal(tmp_path):
    """FFmpeg's own line, `[image2 @ 0x…] Could find no file or sequence …`, went to stderr, where
    the app draws its screen; the one line said is ours (a child process: the terminal's stderr
    is what is checked, and OpenCV reads its FFmpeg log level once a process)."""
    pattern = tmp_path / "pic%03d.png"
    code = (
        "from servant_core.capture.camera import Camera\n"
        "from servant_core.errors import ServantError\n"
        f"try:\n    Camera({str(pattern)!r}).open()\n"
        "except ServantError as error:\n    print(error)\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, env=env
    )
    assert done.stderr == ""
    assert "pic%03d.png" in done.stdout and len(done.stdout.splitlines()) == 1
