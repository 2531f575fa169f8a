"""The motion and ambient senses through the engine, on the paths a wearer takes: logs replayed
by `servant run --imu FILE`, the sensor board's emulator on a real pty, retrain from a library
with logs, saving and loading them in the model file, and teach mode's recording."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from servant_core.capture.sample_files import replay_sample_files
from servant_core.capture.sensor_sources import sensor_sources
from servant_core.capture.source import ManualClock
from servant_core.demo.motion_synth import write_sensor_library
from servant_core.demo.sensor_emulator import SensorEmulator, script_scene
from servant_core.engine import Engine
from servant_core.errors import ServantError
from servant_core.events import DeviceStatus, SensePrediction, SensorFrame, UnknownScene
from servant_core.library import SceneLibrary
from servant_core.modelfile import load_model
from tests.conftest import REPO, servant


@pytest.fixture(scope="module")
def sensor_model(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A model of the motion and ambient senses trained by `servant train` on synthesised logs."""
    base = tmp_path_factory.mktemp("sensors")
    write_sensor_library(base / "library", seed=0, windows_per_scene=8)
    model = base / "model.npz"
    done = servant("train", str(base / "library"), "-o", str(model))
    assert done.returncode == 0, done.stderr
    assert "motion: kmeans" in done.stdout and "ambient: kmeans" in done.stdout
    return model


@pytest.mark.devices
def test_servant_run_replays_motion_and_ambient_logs_end_to_end(sensor_model, tmp_path):
    """`servant run --headless --imu DIR --ambient DIR`: each 5 s window of the logs is judged,
    in the order the logs play (coffee, gym, street: two files each, 5 s a file)."""
    write_sensor_library(tmp_path / "walk", seed=9, windows_per_scene=2)
    args = ["--model", str(sensor_model), "--no-mic", "--no-camera"]
    args += ["--imu", str(tmp_path / "walk"), "--ambient", str(tmp_path / "walk")]
    done = servant("run", "--headless", *args, "--duration", "31")
    assert done.returncode == 0, done.stderr
    felt = re.findall(r"felt \(motion\) (\w+)", done.stdout)
    assert felt[:6] == ["coffee", "coffee", "gym", "gym", "street", "street"], done.stdout
    ambient = re.findall(r"felt \(ambient\) (\w+)", done.stdout)
    assert len(ambient) >= 5 and sum(a == e for a, e in zip(ambient, felt, strict=False)) >= 4


@pytest.mark.devices
def test_servant_run_reads_the_sensor_board_through_the_emulators_pty(sensor_model):
    """The real serial path: `servant emulate-sensors` on a pty, `servant run --imu PORT`."""
    link = Path(f"/tmp/servant-test-sensors-{time.monotonic_ns()}")
    emulator = subprocess.Popen(
        [sys.executable, "-m", "servant_tui", "emulate-sensors", "--script", "gym:600"]
        + ["--link", str(link)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 30
        while not link.exists() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert link.exists(), emulator.stderr.read() if emulator.poll() is not None else ""
        done = servant(
            "run", "--headless", "--model", str(sensor_model), "--no-mic", "--no-camera",
            "--imu", str(link), "--ambient", str(link), "--duration", "12",
        )  # fmt: skip
    finally:
        emulator.terminate()
        emulator.wait(10)
    assert done.returncode == 0, done.stderr
    assert re.search(rf"imu ok: imu sensor on {re.escape(str(link))}", done.stdout), done.stdout
    felt = re.findall(r"felt \(motion\) (\w+)", done.stdout)
    assert len(felt) >= 2 and set(felt) == {"gym"}, done.stdout


@pytest.mark.devices
def test_a_sensor_board_unplugged_is_reported_and_the_engine_goes_on(sensor_model):
    emulator = SensorEmulator(script_scene([("street", 1000.0)]), seed=2)
    port = emulator.start()
    models = load_model(sensor_model)
    sources = sensor_sources({"imu": port})
    engine = Engine(samples={"motion": sources["imu"]}, sample_recognisers=models)
    events: list = []
    engine.subscribe(events.append)
    with engine:
        deadline = time.monotonic() + 20
        while not any(isinstance(e, SensePrediction) for e in events):
            assert time.monotonic() < deadline, events
            time.sleep(0.05)
        emulator.stop()
        while not any(
            isinstance(e, DeviceStatus) and e.device == "imu" and not e.ok for e in events
        ):
            assert time.monotonic() < deadline + 10, events
            time.sleep(0.05)
        assert engine.running  # the loss is a status, not the end of the engine
    said = [e for e in events if isinstance(e, SensePrediction)]
    assert said[0].scene == "street" and said[0].sense == "motion"
    lost = next(e for e in events if isinstance(e, DeviceStatus) and e.device == "imu" and not e.ok)
    assert "\n" not in lost.message and port in lost.message
    assert any(isinstance(e, SensorFrame) and e.rows.shape[1] == 6 for e in events)


def test_retrain_fits_the_sample_senses_of_a_library_and_saves_them(tmp_path):
    root = write_sensor_library(tmp_path / "library", seed=1, windows_per_scene=6)
    library = SceneLibrary.scan(root)
    assert {s: len(f) for s, f in library.samples.items()} == {"motion": 18, "ambient": 18}
    model_path = tmp_path / "model.npz"
    engine = Engine(model_path=model_path)
    progress: list[tuple[int, int]] = []
    engine.retrain(library, on_progress=lambda done, total: progress.append((done, total)))
    assert sorted(engine.sample_recognisers) == ["ambient", "motion"]
    # each sense's 18 logs read, then its fit, a phase of one step (`learning.retrained`)
    sense_phases = [(k, 18) for k in range(1, 19)] + [(0, 1), (1, 1)]
    assert progress == sense_phases * 2
    saved = load_model(model_path)
    assert sorted(saved) == ["ambient", "motion"]
    # and the saved motion recogniser names the scene of a fresh log
    fresh = write_sensor_library(tmp_path / "fresh", seed=7, windows_per_scene=1)
    clock = ManualClock()
    replay = replay_sample_files(
        sorted(Path(fresh).rglob("*.imu.csv")), "imu", realtime=False, clock=clock
    )
    engine = Engine(
        samples={"motion": replay}, sample_recognisers={"motion": saved["motion"]}, clock=clock
    )
    said: list = []
    engine.subscribe(lambda e: said.append(e) if isinstance(e, SensePrediction) else None)
    engine.run_until(1e9)
    assert [e.scene for e in said] == ["coffee", "gym", "street"]


def test_record_samples_gives_the_next_seconds_of_readings():
    emulator = SensorEmulator(script_scene([("coffee", 1000.0)]), seed=4)
    port = emulator.start()
    engine = Engine(samples={"motion": sensor_sources({"imu": port})["imu"]})
    try:
        with engine:
            rows, rate = engine.record_samples("motion", 1.0, timeout=10)
            with pytest.raises(ServantError, match="ambient: not in use"):
                engine.record_samples("ambient", 1.0, timeout=1)
    finally:
        emulator.stop()
    assert rate == 50 and rows.shape == (50, 6) and np.isfinite(rows).all()
    # a still café: gravity, about 9.8 m/s²
    assert 9.0 < float(np.linalg.norm(rows[:, :3], axis=1).mean()) < 10.6


@pytest.mark.devices
def test_the_demo_with_the_learned_fusion_decides_every_place_and_says_what_it_leaned_on():
    """`servant demo --policy learned`: the net is taught on the demo's library at start-up and
    decides from all four senses; every place of the walk is decided, each decision naming the
    senses it leaned on."""
    done = servant("demo", "--headless", "--fast", "--policy", "learned", "--duration", "96")
    assert done.returncode == 0, done.stderr
    decided = re.findall(r"(\w+)Scene detected .*leaned on ([\w, ]+)", done.stdout)
    assert {scene for scene, _ in decided} == {"Coffee", "Gym", "Street"}, done.stdout
    senses = {s.strip() for _, leaned in decided for s in leaned.split(",")}
    assert senses <= {"audio", "image", "motion", "ambient"} and "motion" in senses


@pytest.mark.devices
def test_the_settings_sensor_board_is_used_by_a_plain_servant_run(sensor_model, tmp_path):
    """A wearer sets the sensor board once in Settings (here a folder of logs, as a port would
    be), and `servant run` uses it with no --imu or --ambient; the settings file is the real one
    of the config dir."""
    import os

    from servant_core.settings import Settings, save_settings

    write_sensor_library(tmp_path / "walk", seed=9, windows_per_scene=1)
    save_settings(Settings(sensor_port=str(tmp_path / "walk")))  # the test's own config dir
    args = ["--model", str(sensor_model), "--no-mic", "--no-camera", "--duration", "16"]
    done = servant("run", "--headless", *args, env=dict(os.environ))
    assert done.returncode == 0, done.stderr
    assert re.findall(r"felt \(motion\) (\w+)", done.stdout)[:3] == ["coffee", "gym", "street"]
    assert "ambient ok" in done.stdout


def test_the_demos_sensor_board_starts_with_the_walk_not_when_the_demo_is_built():
    """The demo's training and the app's start-up lie between building the engine and starting
    it; a board emulated from the build on ran that far ahead of the sound. It starts when the
    engine opens it, so the first window's motion is the café's, where the walk begins."""
    from servant_core.engine import build_demo_engine

    engine = build_demo_engine(seed=0, arm=False)
    board = engine.samples["motion"].demo_board
    assert board.emulator.port is None  # nothing streams yet
    time.sleep(2.0)
    said: list = []
    engine.subscribe(lambda e: said.append(e) if isinstance(e, SensePrediction) else None)
    with engine:
        deadline = time.monotonic() + 30
        while not [e for e in said if e.sense == "motion"]:
            assert time.monotonic() < deadline
            time.sleep(0.1)
    assert board.emulator.port is not None
    assert [e for e in said if e.sense == "motion"][0].scene == "coffee"


def test_an_unknown_motion_window_is_asked_about_labelled_and_folded_in(tmp_path):
    """A sample sense meets a place it was not taught: the engine asks (`UnknownScene`, sense
    motion), the label writes the window into the library as a log, and the motion recogniser
    knows the place from then on (folded in, saved with the model). Before, only sound and
    pictures were asked about; a new place felt was never learned."""
    root = write_sensor_library(tmp_path / "library", seed=2, windows_per_scene=8)
    for log in (root / "gym").iterdir():
        log.unlink()  # taught the café and the street only
    library = SceneLibrary.scan(root)
    model_path = tmp_path / "model.npz"
    taught = Engine(model_path=model_path)
    taught.retrain(library)
    gym = write_sensor_library(tmp_path / "new", seed=8, windows_per_scene=2)
    clock = ManualClock()
    replay = replay_sample_files(
        sorted((gym / "gym").glob("*.imu.csv")), "imu", realtime=False, clock=clock
    )
    engine = Engine(
        samples={"motion": replay},
        sample_recognisers={"motion": taught.sample_recognisers["motion"]},
        clock=clock,
        model_path=model_path,
        library_root=root,
    )
    events: list = []
    engine.subscribe(events.append)
    engine.run_until(6.0)  # the first gym window
    [asked] = [e for e in events if isinstance(e, UnknownScene)]
    assert asked.sense == "motion" and asked.window_id.startswith("motion-")
    written = engine.label_unknown(asked.window_id, "gym")
    assert written.parent == root / "gym" and written.name.endswith(".imu.csv")
    assert written in [f.path for f in SceneLibrary.scan(root).samples["motion"]]  # read as a log
    events.clear()
    engine.run_until(1e9)  # the second gym window, never heard before
    felt = [e.scene for e in events if isinstance(e, SensePrediction)]
    assert felt == ["gym"], events
    assert "gym" in load_model(model_path)["motion"].scenes_


def test_a_sample_sense_is_not_asked_about_a_place_another_sense_names(tmp_path):
    """Motion does not know the gym, but the ambient sense, taught it, names it: the wearer is
    not asked what motion felt (Servant knows where they are). Before, every unknown motion or
    ambient window raised the "What is this place?" prompt, even while the other senses agreed."""
    root = write_sensor_library(tmp_path / "library", seed=2, windows_per_scene=8)
    for log in (root / "gym").glob("*.imu.csv"):
        log.unlink()  # motion taught the café and the street; ambient all three
    taught = Engine()
    taught.retrain(SceneLibrary.scan(root))
    gym = sorted(
        (write_sensor_library(tmp_path / "new", seed=8, windows_per_scene=3) / "gym").iterdir()
    )
    clock = ManualClock()
    engine = Engine(
        samples={
            "motion": replay_sample_files(
                [p for p in gym if p.name.endswith(".imu.csv")], "imu", realtime=False, clock=clock
            ),
            "ambient": replay_sample_files(
                [p for p in gym if p.name.endswith(".ambient.csv")],
                "ambient",
                realtime=False,
                clock=clock,
            ),
        },
        sample_recognisers=dict(taught.sample_recognisers),
        clock=clock,
    )
    events: list = []
    engine.subscribe(events.append)
    engine.run_until(1e9)
    said = [(e.sense, e.scene) for e in events if isinstance(e, SensePrediction)]
    assert ("motion", None) in said and ("ambient", "gym") in said, said
    first_named = next(i for i, e in enumerate(events) if getattr(e, "scene", None) == "gym")
    asked_after = [e for e in events[first_named:] if isinstance(e, UnknownScene)]
    assert asked_after == []
