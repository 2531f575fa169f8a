"""A recording stops at once when asked to (issue 39 item 9): `q` during teach mode's 5 s
recording left a blank terminal for 12 s, the recording waiting out its timeout for sound the
stopped engine no longer read. Stopped, it keeps nothing of its own and loses nothing saved."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest
from textual.widgets import Input

from servant_core.audio import write_wav
from servant_core.capture.replay import Clip, PacedAudio
from servant_core.capture.sample_files import replay_sample_files, write_sample_csv
from servant_core.engine import Engine
from servant_core.errors import ServantError
from servant_tui.app import ServantApp
from servant_tui.screens.teach import TeachScreen
from tests.test_tui_live import log_text, settle
from tests.tui_library import RATE, noise_recording

# Asked to stop, a recording ends within this (it checks for the request every few hundredths)
PROMPTLY_S = 1.0


def as_a_microphone() -> PacedAudio:
    """A minute of noise, given as a microphone gives it: a second of sound a second."""
    return PacedAudio([Clip(None, noise_recording(60.0, 500.0, seed=1))], RATE, realtime=True)


def test_a_recording_asked_to_stop_ends_at_once_and_says_so():
    engine = Engine(audio=as_a_microphone())
    cancel = threading.Event()
    with engine:
        threading.Timer(0.3, cancel.set).start()
        begun = time.monotonic()
        with pytest.raises(ServantError, match="stopped .* not kept"):
            engine.record_window(5.0, cancel=cancel)
        assert time.monotonic() - begun < 0.3 + PROMPTLY_S


def test_a_recording_ends_at_once_when_the_engine_stops():
    engine = Engine(audio=as_a_microphone())
    engine.start()
    ended: list[float] = []
    raised: list[BaseException] = []

    def record() -> None:
        try:
            engine.record_window(5.0, timeout=6.0)
        except ServantError as error:
            raised.append(error)
        ended.append(time.monotonic())

    recorder = threading.Thread(target=record)
    recorder.start()
    time.sleep(0.3)
    stopped = time.monotonic()
    engine.stop()
    recorder.join(10)
    assert raised, "a recording cut short by the engine stopping returned sound"
    assert ended[0] - stopped < PROMPTLY_S, f"it ended {ended[0] - stopped:.1f} s after the stop"


def test_a_sample_sense_recording_asked_to_stop_ends_at_once(tmp_path):
    rows = np.tile(np.array([[0.0, 0.0, 9.8, 0.0, 0.0, 0.0]], dtype=np.float32), (50 * 60, 1))
    log = write_sample_csv(tmp_path / "still.imu.csv", rows, 50, "imu")
    engine = Engine(samples={"motion": replay_sample_files([log], "imu", realtime=True)})
    cancel = threading.Event()
    with engine:
        threading.Timer(0.3, cancel.set).start()
        begun = time.monotonic()
        with pytest.raises(ServantError, match="stopped .* not kept"):
            engine.record_samples("motion", 5.0, None, cancel=cancel)
        assert time.monotonic() - begun < 0.3 + PROMPTLY_S


class WatchedEngine(Engine):
    """A real engine that says when teach mode's recording began and when it ended."""

    def __init__(self, **options) -> None:
        super().__init__(**options)
        self.recording = threading.Event()
        self.recorded = threading.Event()

    def record_window(self, *args, **options) -> np.ndarray:
        self.recording.set()
        try:
            return super().record_window(*args, **options)
        finally:
            self.recorded.set()


async def recording_in_teach_mode(pilot, app: ServantApp, engine: WatchedEngine) -> TeachScreen:
    await settle(pilot, lambda: engine.running)
    await pilot.press("t")
    await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
    screen = app.screen
    screen.query_one("#new-scene", Input).value = "cafe"
    screen.use_scene()
    await pilot.pause()
    await pilot.click("#record")
    await settle(pilot, lambda: engine.recording.is_set())
    await pilot.pause(0.5)  # half a second into the 5 s
    return screen


def library_files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


async def test_quitting_during_a_teach_recording_stops_it_at_once_and_keeps_what_was_saved(
    tmp_path, monkeypatch
):
    monkeypatch.setenv("SERVANT_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    root = tmp_path / "library"
    write_wav(root / "cafe" / "teach-earlier.wav", noise_recording(5.0, 500.0, seed=2), RATE)
    engine = WatchedEngine(audio=as_a_microphone(), library_root=root)
    app = ServantApp(engine, library_root=root)
    async with app.run_test(size=(120, 40)) as pilot:
        await recording_in_teach_mode(pilot, app, engine)
        quit_at = time.monotonic()
        await pilot.press("q")
    # the app's worker threads are waited for as it exits: the recording is what kept it
    assert engine.recorded.wait(PROMPTLY_S), (
        f"the recording was still going {time.monotonic() - quit_at:.1f} s after q"
    )
    time.sleep(0.3)  # a recording that went on to write would have written by now
    assert library_files(root) == ["cafe/teach-earlier.wav"], "half a recording was kept"


async def test_leaving_teach_mode_during_a_recording_stops_it_and_says_it_was_not_kept(
    tmp_path, monkeypatch
):
    monkeypatch.setenv("SERVANT_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    root = tmp_path / "library"
    engine = WatchedEngine(audio=as_a_microphone(), library_root=root)
    app = ServantApp(engine, library_root=root)
    async with app.run_test(size=(120, 40)) as pilot:
        await recording_in_teach_mode(pilot, app, engine)
        await pilot.press("escape")
        assert engine.recorded.wait(PROMPTLY_S), "the recording went on after teach mode closed"
        await settle(pilot, lambda: "not kept" in log_text(app))
        assert "recording" in log_text(app)
        await pilot.pause(0.3)
        assert not list(root.rglob("*.wav")), "half a recording was kept"
        assert engine.running, "leaving teach mode stopped more than the recording"
