"""Numbers read from files are checked as numbers before they are converted (issue 24 item 3):
an integer beyond the float range is refused where it is read, never an `OverflowError` later."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import servant_core.capture.sample_files as sample_files
from servant_core.actions.records import (
    MAX_SCENES,
    TeachRecord,
    append_record,
    label_scores,
    load_records,
    save_records,
)
from servant_core.capture.sample_files import MAX_LOG_SECONDS, read_sample_csv, read_samples
from servant_core.capture.sensors import parse_line
from servant_core.errors import ServantError
from servant_core.numbers import FLOAT_MAX, is_finite_number, json_loads
from servant_core.servo.calibration import clamp_pose
from servant_core.settings import default_joints
from tests.cli_harness import assert_clear, assert_refused, run_cli, run_cli_subprocess

HUGE = 10**400


def test_is_finite_number_checks_integers_before_converting() -> None:
    assert is_finite_number(3) and is_finite_number(-2.5) and is_finite_number(int(FLOAT_MAX))
    for value in (HUGE, -HUGE, float("nan"), float("inf"), True, "1", None):
        assert not is_finite_number(value)


def test_json_loads_refuses_an_integer_beyond_floats() -> None:
    assert json_loads('{"a": [1, -2, 3.5]}') == {"a": [1, -2, 3.5]}
    with pytest.raises(ValueError, match="too large"):
        json_loads(f"[{HUGE}]")


def test_a_sensor_log_row_stamped_beyond_floats_is_skipped(tmp_path: Path) -> None:
    log = tmp_path / "walk.imu.csv"
    rows = [f"{i * 0.01:.2f},0,0,9.8,0,0,0" for i in range(50)]
    rows.insert(10, f"{HUGE},0,0,9.8,0,0,0")
    rows.insert(20, f"{'9' * 5000},0,0,9.8,0,0,0")  # beyond Python's own 4300 digits
    log.write_text("time,ax,ay,az,gx,gy,gz\n" + "\n".join(rows) + "\n")
    read = read_sample_csv(log, "imu")
    assert read.skipped == 2 and len(read.times) == 50


def test_train_on_a_log_of_huge_stamps_is_one_line(tmp_path: Path) -> None:
    for scene in ("cafe", "gym"):
        (tmp_path / "lib" / scene).mkdir(parents=True)
        rows = [f"{HUGE + i},0,0,9.8,0,0,0" for i in range(600)]
        (tmp_path / "lib" / scene / "a.imu.csv").write_text(
            "time,ax,ay,az,gx,gy,gz\n" + "\n".join(rows) + "\n"
        )
    for skip in ([], ["--skip-bad"]):
        outcome = run_cli("train", str(tmp_path / "lib"), "-o", str(tmp_path / "m.npz"), *skip)
        assert_clear(outcome)
        assert outcome.code == 2


def test_a_board_line_stamped_beyond_floats_is_refused() -> None:
    with pytest.raises(ValueError):
        parse_line(f"I,{HUGE},0,0,9.8,0,0,0\n".encode())


def test_a_pose_beyond_floats_is_refused_in_one_line() -> None:
    joints = {j.name: j for j in default_joints()}
    with pytest.raises(ServantError, match="not an angle"):
        clamp_pose(joints, {"shoulder": HUGE})


def test_a_log_of_rows_just_under_a_gap_apart_is_refused_before_resampling(
    tmp_path: Path,
) -> None:
    """Issue 24 item 6: rows 0.99 s apart resample to 50 samples each at 50 Hz: 20,000 rows
    (1 MB) would be a million samples; 300,000 such rows would be gigabytes. The span is
    checked before the grid is made."""
    log = tmp_path / "slow.imu.csv"
    rows = int(MAX_LOG_SECONDS / 0.99) + 100
    log.write_text(
        "time,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 0.99:.2f},0,0,9.8,0,0,0\n" for i in range(rows))
    )
    with pytest.raises(ServantError, match="span more than 4 hours"):
        read_samples(log, "imu")
    short = tmp_path / "short.imu.csv"
    short.write_text(
        "time,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 0.99:.2f},0,0,9.8,0,0,0\n" for i in range(50))
    )
    assert read_samples(short, "imu").shape[1] == 6


def test_a_log_of_too_many_rows_is_refused_while_reading(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sample_files, "MAX_ROWS", 100)
    log = tmp_path / "long.imu.csv"
    log.write_text(
        "time,ax,ay,az,gx,gy,gz\n" + "".join(f"{i * 0.01:.2f},0,0,9.8,0,0,0\n" for i in range(101))
    )
    with pytest.raises(ServantError, match="more than 100 readings"):
        read_sample_csv(log, "imu")


def test_teach_records_are_bounded_in_scenes_and_records(tmp_path: Path) -> None:
    """Issue 24 item 6: 20,000 scenes in the teach records once asked the learner for 3.5 GB."""
    path = tmp_path / "records.json"
    records = [
        {"scene": f"s{i}", "scores": label_scores(f"s{i}"), "pose": {"shoulder": 1.0}, "t": 0}
        for i in range(MAX_SCENES + 1)
    ]
    path.write_text(
        json.dumps({"format": "servant-teach-records", "version": 2, "records": records})
    )
    with pytest.raises(ServantError, match=f"more than {MAX_SCENES} scenes"):
        load_records(path)
    wide = {f"s{i}": 0.0 for i in range(MAX_SCENES + 1)}
    records = [{"scene": "a", "scores": {"acoustic": wide}, "pose": {"shoulder": 1.0}, "t": 0}]
    path.write_text(
        json.dumps({"format": "servant-teach-records", "version": 2, "records": records})
    )
    with pytest.raises(ServantError, match="more than"):
        load_records(path)
    full = tmp_path / "full.json"
    few = [
        TeachRecord(f"s{i}", label_scores(f"s{i}"), {"shoulder": 1.0}, 0.0)
        for i in range(MAX_SCENES)
    ]
    save_records(few, full)
    before = full.read_bytes()
    with pytest.raises(ServantError, match="nothing was added"):
        append_record(
            TeachRecord("one-more", label_scores("one-more"), {"shoulder": 1.0}, 0.0), full
        )
    assert full.read_bytes() == before


@pytest.mark.devices
@pytest.mark.parametrize("speed", ["4.9e-324", "1e-300", "0.001"])
def test_a_joint_speed_too_small_to_finish_a_move_is_refused(tmp_path: Path, speed: str) -> None:
    """A speed above 0 but tiny made `servo move` wait for ever (the move needs 5/5e-324 s,
    which is infinity): a hang, where a line that says so was due."""
    joint = (
        '{"name": "shoulder", "channel": 3, "min_angle": 0, "max_angle": 90, "min_pulse_us": '
        f'1000, "max_pulse_us": 1500, "max_speed_deg_s": {speed}, "home_angle": 0}}'
    )
    path = tmp_path / "settings.json"
    path.write_text(f'{{"format": "servant-settings", "version": 1, "joints": [{joint}]}}')
    outcome = run_cli_subprocess(
        "servo", "move", "--settings", str(path), "--dry-run", "shoulder=5", timeout=20
    )
    assert_refused(outcome, "max_speed_deg_s", "from 1 to")
