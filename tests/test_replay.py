"""Replaying recordings and pictures as if live: pacing, clocks, bad files, matching pictures."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from servant_core.audio import write_wav
from servant_core.capture.replay import Clip, PacedAudio, PictureReplay, replay_recordings
from servant_core.capture.ring import RingBuffer
from servant_core.capture.source import ManualClock
from servant_core.errors import ServantError
from servant_core.library import Picture, Recording
from tests.conftest import tone


def drain(source, limit: int = 100_000) -> tuple[np.ndarray, list[str]]:
    """Everything a finite source gives, and the errors it raised on the way."""
    blocks, errors = [], []
    source.open()
    for _ in range(limit):
        try:
            block = source.read(0.5)
        except ServantError as error:
            errors.append(str(error))
            continue
        if block is not None:
            blocks.append(block)
        elif source.exhausted:
            break
    return np.concatenate(blocks), errors


def test_as_fast_as_possible_advances_a_manual_clock_by_the_audio_played():
    clock = ManualClock()
    rate = 8000
    clips = [Clip("a", tone(440, 1.5, rate)), Clip("b", tone(880, 0.75, rate))]
    started = time.monotonic()
    audio, errors = drain(PacedAudio(clips, rate, realtime=False, clock=clock))
    assert time.monotonic() - started < 1.0  # 2.25 s of audio, no sleeping
    assert not errors
    assert np.array_equal(audio, np.concatenate([c.samples for c in clips]))
    assert clock() == pytest.approx(2.25, abs=1e-9)


def test_at_real_speed_blocks_arrive_no_faster_than_a_microphone_would():
    rate = 8000
    source = PacedAudio([Clip("a", tone(440, 1.0, rate))], rate, realtime=True)
    started = time.monotonic()
    audio, _ = drain(source)
    assert len(audio) == rate
    assert time.monotonic() - started >= 0.95


def test_a_corrupt_file_is_reported_once_and_the_replay_goes_on(tmp_path):
    rate = 8000
    good1 = write_wav(tmp_path / "one.wav", tone(300, 0.5, rate), rate)
    bad = tmp_path / "broken.wav"
    bad.write_bytes(b"RIFF\x00\x00\x00\x00WAVEfmt garbage")
    good2 = write_wav(tmp_path / "two.wav", tone(600, 0.5, rate), rate)
    source = replay_recordings([good1, bad, good2], rate, realtime=False, clock=ManualClock())
    audio, errors = drain(source)
    assert (
        len(errors) == 1 and "broken.wav" in errors[0] and "not a readable audio file" in errors[0]
    )
    assert len(audio) == rate  # both good halves, nothing from the bad one
    assert source.current_label == "two"


def test_pictures_follow_the_scene_being_heard_and_a_bad_one_is_dropped(tmp_path):
    pictures = []
    for scene, colour in (("red", (0, 0, 255)), ("blue", (255, 0, 0))):
        for i in range(2):
            path = tmp_path / scene / f"{i}.png"
            path.parent.mkdir(exist_ok=True)
            cv2.imwrite(str(path), np.full((8, 8, 3), colour, np.uint8))
            pictures.append(Picture(scene, path))
    bad = tmp_path / "blue" / "bad.png"
    bad.write_text("not a picture")
    pictures.append(Picture("blue", bad))
    heard = {"scene": "red"}
    replay = PictureReplay(pictures, scene_of=lambda: heard["scene"])
    replay.open()
    assert all(replay.read()[0, 0, 2] == 255 for _ in range(3))
    heard["scene"] = "blue"
    blues, errors = [], []
    for _ in range(6):
        try:
            blues.append(replay.read())
        except ServantError as error:
            errors.append(str(error))
    assert len(errors) == 1 and "bad.png" in errors[0]
    assert len(blues) == 5 and all(b[0, 0, 0] == 255 for b in blues)


def test_ring_buffer_cuts_by_absolute_position_across_the_wrap():
    ring = RingBuffer(10)
    signal = np.arange(27, dtype=np.float32)
    for start in range(0, 27, 4):
        ring.append(signal[start : start + 4])
    assert ring.total == 27
    assert np.array_equal(ring.read(17, 27), signal[17:27])  # wraps inside the array
    assert np.array_equal(ring.latest(3), signal[24:27])
    with pytest.raises(IndexError):
        ring.read(16, 20)  # overwritten already
    with pytest.raises(IndexError):
        ring.read(25, 28)  # not yet written
    ring.append(np.arange(100, 125, dtype=np.float32))  # a block longer than the ring
    assert ring.total == 52 and np.array_equal(ring.latest(10), np.arange(115, 125))


def test_recordings_keep_their_scene_as_label(tmp_path):
    rate = 8000
    path = write_wav(tmp_path / "cafe" / "x.wav", tone(300, 0.2, rate), rate)
    source = replay_recordings([Recording("cafe", path)], rate, realtime=False)
    drain(source)
    assert source.current_label == "cafe"
