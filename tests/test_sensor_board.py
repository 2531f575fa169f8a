"""The motion and ambient sensor board: its lines, the real serial path through the emulator's
pty (pyserial), a vanished port, and CSV logs replayed."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from servant_core.capture.sample_files import (
    read_sample_csv,
    read_samples,
    replay_sample_files,
    write_sample_csv,
)
from servant_core.capture.sensor_sources import sensor_sources
from servant_core.capture.sensors import (
    IMU_CHANNELS,
    SensorBoard,
    format_line,
    parse_line,
)
from servant_core.capture.source import ManualClock, SampleSource
from servant_core.demo.sensor_emulator import SensorEmulator, parse_script, script_scene
from servant_core.errors import ServantError
from tests.conftest import serve


def read_rows(source, seconds: float) -> np.ndarray:
    """Everything a source gives in `seconds` of wall time."""
    blocks, deadline = [], time.monotonic() + seconds
    while time.monotonic() < deadline:
        block = source.read(0.05)
        if block is not None:
            blocks.append(block)
    return np.concatenate(blocks) if blocks else np.empty((0, len(source.channels)))


def test_lines_parse_and_format_both_ways():
    line = format_line("imu", 1234, (0.1, -0.2, 9.81, 1.5, -2.25, 0.0))
    assert line == b"I,1234,0.100,-0.200,9.810,1.500,-2.250,0.000\n"
    reading = parse_line(line)
    assert reading is not None and reading.kind == "imu" and reading.millis == 1234
    assert reading.values == pytest.approx((0.1, -0.2, 9.81, 1.5, -2.25, 0.0))
    ambient = parse_line(b"A,20,312.5,21.75,1012.40\r\n")
    assert ambient is not None and ambient.values == pytest.approx((312.5, 21.75, 1012.4))
    assert parse_line(b"# banner\n") is None and parse_line(b"\n") is None


@pytest.mark.parametrize(
    "bad",
    [b"X,1,2,3\n", b"I,12,1,2,3\n", b"I,12,1,2,3,4,5,nan\n", b"A,-5,1,2,3\n", b"I,a,1,2,3,4,5,6\n"],
)
def test_bad_lines_are_refused(bad):
    with pytest.raises(ValueError):
        parse_line(bad)


def test_the_board_streams_both_senses_through_the_pty_and_counts_a_bad_line():
    emulator = SensorEmulator(script_scene([("street", 1000.0)]), seed=3)
    port = emulator.start()
    board = SensorBoard(port)
    imu, ambient = board.source("imu"), board.source("ambient")
    assert isinstance(imu, SampleSource) and imu.channels == IMU_CHANNELS
    try:
        imu.open()
        ambient.open()
        first = read_rows(imu, 1.0)
        before = board.bad_lines
        emulator.inject(b"I,99,not,a,number,at,all,!\n")
        second = read_rows(imu, 0.6)
        light = ambient.read(1.0)
        assert board.bad_lines == before + 1
        assert board.measured_rate("imu") == pytest.approx(50, rel=0.05)
        motion = np.concatenate([first, second])
        # 50 lines a second arrive (the first second's backlog aside), as float32 (n, 6)
        assert motion.dtype == np.float32 and motion.shape[1] == 6
        assert 60 <= len(motion) <= 120
        # gravity is in the readings: the acceleration's magnitude averages about 9.8 m/s²
        assert np.linalg.norm(motion[:, :3], axis=1).mean() == pytest.approx(9.8, abs=0.6)
        assert light is not None and light.shape[1] == 3 and np.all(light[:, 0] > 1000)
    finally:
        imu.close()
        ambient.close()
        emulator.stop()


def test_a_vanished_port_is_one_clear_error_and_the_source_reopens():
    emulator = SensorEmulator(script_scene([("coffee", 1000.0)]))
    port = emulator.start()
    source = SensorBoard(port).source("imu")
    source.open()
    assert read_rows(source, 0.3).size
    emulator.stop()
    with pytest.raises(ServantError) as caught:
        read_rows(source, 1.0)
    message = str(caught.value)
    assert "\n" not in message and message.startswith(port)
    assert re.search(r"sensor board was lost|no such serial port", message)
    source.close()
    with pytest.raises(ServantError, match="no such serial port"):
        source.open()
    source.close()


@pytest.mark.devices
def test_emulate_sensors_command_serves_until_killed():
    # its own process: killing it unplugs the board for real
    proc, port = serve("emulate-sensors", "--script", "gym:5,coffee:5")
    try:
        source = SensorBoard(port).source("imu")
        source.open()
        rows = read_rows(source, 0.5)
        assert rows.shape[1] == 6 and len(rows) > 10
    finally:
        proc.kill()
        proc.wait()
    with pytest.raises(ServantError, match="lost"):
        read_rows(source, 1.0)
    source.close()


def test_a_bad_scene_script_is_one_line():
    assert parse_script("coffee:20, gym:5") == [("coffee", 20.0), ("gym", 5.0)]
    for text in ("coffee:-1", "coffee:x", ":4", ""):
        with pytest.raises(ServantError, match="coffee:20"):
            parse_script(text)


def test_the_emulator_is_the_same_stream_for_the_same_seed():
    a = SensorEmulator(script_scene([("gym", 2.0), ("street", 2.0)]), seed=1)
    b = SensorEmulator(script_scene([("gym", 2.0), ("street", 2.0)]), seed=1)
    assert a.lines_between(0, 6) == b.lines_between(0, 6)
    lines = a.lines_between(0, 1).splitlines()
    # one second: 50 motion lines and 2 ambient lines, in time order
    assert sum(line.startswith(b"I,") for line in lines) == 50
    assert sum(line.startswith(b"A,") for line in lines) == 2


PHONE_LOG = """\
time,seconds_elapsed,accX,accY,accZ,gyroX,gyroY,gyroZ,extra
1700000000000000000,0,0,0,9.81,0,0,0,x
1700000000010000000,0.01,0.1,0,9.81,0,0,0,x
not,a,row,at,all,,,
1700000000020000000,0.02,0.2,0,9.81,0,0,0,x
1700000000030000000,0.03,0.3,0,9.81,0,0,0,x
"""


def test_a_phone_log_with_nanosecond_stamps_reads_and_a_bad_row_is_skipped(tmp_path):
    path = tmp_path / "walk.imu.csv"
    path.write_text(PHONE_LOG)
    log = read_sample_csv(path, "imu")
    assert log.skipped == 1
    assert log.times == pytest.approx([0.0, 0.01, 0.02, 0.03])
    assert log.values[:, 0] == pytest.approx([0.0, 0.1, 0.2, 0.3])
    # resampled to 50 Hz: readings at 0 and 0.02 s, by linear interpolation
    assert read_samples(path, "imu")[:, 0] == pytest.approx([0.0, 0.2])


def test_units_in_brackets_convert(tmp_path):
    path = tmp_path / "x.csv"
    path.write_text(
        "Time (s),Acceleration x (g),Acceleration y (g),Acceleration z (g),"
        "Gyroscope x (rad/s),Gyroscope y (rad/s),Gyroscope z (rad/s)\n"
        "0,0,0,1,3.14159265,0,0\n0.5,0,0,1,0,0,0\n"
    )
    log = read_sample_csv(path, "imu")
    assert log.values[0, 2] == pytest.approx(9.80665) and log.values[0, 3] == pytest.approx(180)
    ambient = tmp_path / "a.csv"
    ambient.write_text(
        "time_ms,Illuminance (lx),Temperature,Pressure (Pa)\n0,10,20,101325\n500,11,20,101325\n"
    )
    log = read_sample_csv(ambient, "ambient")
    assert log.times == pytest.approx([0, 0.5]) and log.values[0, 2] == pytest.approx(1013.25)


@pytest.mark.parametrize(
    ("content", "said"),
    [
        ("", "empty"),
        ("time,ax,ay,az,gx,gy\n0,1,2,3,4,5\n", "no gz column"),
        ("time,ax,ay,az,gx,gy,gz\n0,1,2,3,4,5,6\n", "fewer than two readings"),
    ],
)
def test_unusable_logs_are_one_line(tmp_path, content, said):
    path = tmp_path / "bad.imu.csv"
    path.write_text(content)
    with pytest.raises(ServantError, match=said) as caught:
        read_sample_csv(path, "imu")
    assert "\n" not in str(caught.value)


def test_a_replay_gives_windows_in_order_advances_the_clock_and_skips_a_bad_file(tmp_path):
    rng = np.random.default_rng(0)
    first = rng.normal(size=(100, 6)).astype(np.float32)
    second = rng.normal(size=(50, 6)).astype(np.float32)
    write_sample_csv(tmp_path / "a.imu.csv", first, 50, "imu")
    (tmp_path / "broken.imu.csv").write_text("nothing useful\n")
    write_sample_csv(tmp_path / "b.imu.csv", second, 50, "imu")
    clock = ManualClock()
    source = replay_sample_files(
        [
            ("coffee", tmp_path / "a.imu.csv"),
            ("x", tmp_path / "broken.imu.csv"),
            ("gym", tmp_path / "b.imu.csv"),
        ],
        "imu",
        realtime=False,
        clock=clock,
    )
    assert isinstance(source, SampleSource) and not source.live
    source.open()
    blocks, labels, errors = [], [], []
    while not source.exhausted:
        try:
            block = source.read(0.1)
        except ServantError as error:
            errors.append(str(error))
            continue
        if block is not None:
            blocks.append(block)
            labels.append(source.current_label)
    assert len(errors) == 1 and "broken.imu.csv" in errors[0]
    assert np.concatenate(blocks) == pytest.approx(np.concatenate([first, second]), abs=1e-4)
    assert clock() == pytest.approx(3.0)  # 150 readings at 50 Hz
    assert labels[0] == "coffee" and labels[-1] == "gym"


def test_a_replay_that_follows_another_clock_waits_for_it(tmp_path):
    write_sample_csv(tmp_path / "a.ambient.csv", np.ones((20, 3)), 2, "ambient")
    clock = ManualClock()
    source = replay_sample_files(
        [tmp_path / "a.ambient.csv"], "ambient", realtime=False, follow=clock, block_seconds=0.5
    )
    source.open()
    assert source.read(0.0) is None  # the audio has not played a reading's worth yet
    clock.advance(2.0)
    got = [source.read(0.0) for _ in range(10)]
    assert sum(len(b) for b in got if b is not None) == 4


def test_one_port_named_for_both_streams_is_one_board_and_a_folder_replays_by_scene(tmp_path):
    emulator = SensorEmulator(script_scene([("gym", 1000.0)]))
    port = emulator.start()
    write_sample_csv(tmp_path / "gym" / "a.ambient.csv", np.ones((10, 3)), 2, "ambient")
    write_sample_csv(tmp_path / "cafe" / "b.ambient.csv", np.ones((10, 3)), 2, "ambient")
    try:
        both = sensor_sources({"imu": port, "ambient": port})
        assert both["imu"].board is both["ambient"].board  # opened once: the port is exclusive
        for source in both.values():
            source.open()
        assert read_rows(both["imu"], 0.3).shape[1] == 6
        for source in both.values():
            source.close()
        mixed = sensor_sources({"imu": port, "ambient": str(tmp_path)}, realtime=False)
        replay = mixed["ambient"]
        replay.open()
        replay.read(0.0)
        assert replay.current_label == "cafe" and mixed["imu"].live and not replay.live
        with pytest.raises(ServantError, match="no .imu.csv files"):
            sensor_sources({"imu": str(tmp_path)})
    finally:
        emulator.stop()


def test_the_emulators_light_and_warmth_do_not_jump_within_one_stay():
    """The board synthesises five seconds at a time; a window the engine cuts across two of
    them must not see the room's light jump, as no real room's does (it once read as an unknown
    place at every window of the live demo)."""
    emulator = SensorEmulator(script_scene([("street", 1000.0)]), seed=5)
    lines = [parse_line(line) for line in emulator.lines_between(0, 30).splitlines()]
    ambient = np.array([r.values for r in lines if r is not None and r.kind == "ambient"])
    assert len(ambient) == 60
    stretches = np.log(ambient[:, 0]).reshape(6, 10).mean(axis=1)  # each 5 s stretch's light
    assert np.ptp(stretches) < 0.1  # per-stretch noise only; a new spot would move it ~0.25
    assert np.ptp(ambient[:, 1].reshape(6, 10).mean(axis=1)) < 0.2
