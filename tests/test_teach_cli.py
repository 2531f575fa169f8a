"""`servant teach` (the paper's Fig. 6 session), `servant servo ...` and `servant emulate-servo`."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys

import pytest

from servant_core.actions.records import load_records
from servant_core.cli import main
from servant_core.servo.emulator import start_emulator
from servant_core.settings import default_joints
from tests.conftest import serve

FIG6 = "coffee\n42\ngym\n10\n\ncoffee\ngym\n"


def run(argv, stdin, monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", io.StringIO(stdin))
    status = main(argv)
    out, err = capsys.readouterr()
    return status, out, err


def test_fig6_session_reproduces(monkeypatch, capsys):
    status, out, _ = run(["teach"], FIG6, monkeypatch, capsys)
    assert status == 0
    lines = out.splitlines()
    assert [
        line for line in lines if line.startswith(("Scene label:", "What action", "Tell me"))
    ] == [
        "Scene label: coffee",
        "What action should I take? 42",
        "Scene label: gym",
        "What action should I take? 10",
        "Scene label: ",
        "Tell me something: coffee",
        "Tell me something: gym",
        "Tell me something: ",
    ]
    errors = [
        float(m.group(2)) for m in re.finditer(r"Error after (\d+) iterations?: ([\d.]+)", out)
    ]
    assert len(errors) == 4 and errors[-1] < errors[0] / 100
    answers = lines[lines.index("Tell me something: coffee") + 1 :]
    assert answers[0] == "42" and answers[2] == "10"
    assert [(r.scene, r.pose) for r in load_records()] == [
        ("coffee", {"shoulder": 42.0}),
        ("gym", {"shoulder": 10.0}),
    ]

    # A later session asks the saved learner without training again.
    status, out, _ = run(["teach", "--predict-only"], "gym\nlibrary\n", monkeypatch, capsys)
    assert status == 0
    assert "Tell me something: gym\n10\n" in out
    assert "never taught what to do in 'library'" in out


def test_bad_answers_are_asked_again_never_crash(monkeypatch, capsys):
    session = (
        "coffee\n\nlots\nwrist=10\n200\ngym\nshoulder=5, elbow=30\nstreet\n"  # ends mid-answer
    )
    status, out, _ = run(["teach", "--iterations", "50"], session, monkeypatch, capsys)
    assert status == 0
    assert "no action given" in out
    assert "'lots' is not an angle" in out
    assert "no joint named 'wrist'" in out
    assert "shoulder: 200 is beyond 0..90 degrees, clamped to 90" in out
    assert "No action for street; nothing recorded." in out
    records = load_records()
    assert [(r.scene, r.pose) for r in records] == [
        ("coffee", {"shoulder": 90.0}),
        ("gym", {"shoulder": 5.0, "elbow": 30.0}),
    ]


def test_nothing_taught_is_said(monkeypatch, capsys):
    """One error line and status 2, as for every other error (issue 24 item 8: it was a line on
    stdout and status 1)."""
    status, _, err = run(["teach"], "\n", monkeypatch, capsys)
    assert status == 2 and err.startswith("servant: error: nothing to learn from")
    assert err.count("\n") == 1


def test_teach_with_a_port_moves_the_emulated_arm(monkeypatch, capsys):
    emulator, port = start_emulator("firmata")
    try:
        argv = ["teach", "--port", port, "--protocol", "firmata", "--iterations", "1000"]
        status, out, _ = run(argv, "coffee\n20\n\ncoffee\n", monkeypatch, capsys)
    finally:
        emulator.stop()
    assert status == 0, out
    assert "The arm is armed on" in out
    shoulder = default_joints()[0]
    assert emulator.pulse(shoulder.channel) == pytest.approx(1000 + 20 * 500 / 90, abs=1)


def test_servo_move_dry_run_prints_the_bytes(monkeypatch, capsys):
    status, out, _ = run(
        ["servo", "move", "--dry-run", "--protocol", "ssc32", "shoulder=3"], "", monkeypatch, capsys
    )
    assert status == 0
    assert "bytes: '#3P1000S166#4P1500S250#5P1000S333\\r'" in out  # arming: home
    assert "bytes: '#3P1017S166\\r'" in out  # 3 degrees, rate-limited: the last step
    assert out.rstrip().endswith("moved to shoulder 3°")  # the joint named (issue 22 item 14)


def test_servo_move_beyond_the_limit_names_the_joint_it_moved(monkeypatch, capsys):
    status, out, _ = run(["servo", "move", "--dry-run", "shoulder=400"], "", monkeypatch, capsys)
    assert status == 0
    assert "shoulder: 400 is beyond" in out and out.rstrip().endswith("moved to shoulder 90°")


def test_servo_query_and_errors(monkeypatch, capsys):
    emulator, port = start_emulator("maestro")
    try:
        run(["servo", "home", "--port", port], "", monkeypatch, capsys)
        status, out, _ = run(["servo", "query", "--port", port, "--json"], "", monkeypatch, capsys)
    finally:
        emulator.stop()
    assert status == 0
    assert json.loads(out)["angles"] == pytest.approx(
        {"shoulder": 0.0, "elbow": 90.0, "gripper": 0.0}
    )
    status, _, err = run(
        ["servo", "query", "--port", "/dev/nonexistent-servo"], "", monkeypatch, capsys
    )
    assert status == 2 and err.startswith(
        "servant: error: /dev/nonexistent-servo: no such serial port"
    )
    status, _, err = run(["servo", "move", "--dry-run", "elbow=abc"], "", monkeypatch, capsys)
    assert status == 2 and "'elbow=abc' is not an angle" in err


@pytest.mark.devices
def test_emulate_servo_prints_the_port_to_connect_to():
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "servant_tui",
            "emulate-servo",
            "--protocol",
            "ssc32",
            "--seconds",
            "0.2",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    assert re.match(r"Emulating a Lynxmotion SSC-32 on /dev/pts/\d+; connect with", proc.stdout)


@pytest.mark.devices
def test_teach_survives_the_controller_killed_while_idle(tmp_path):
    # Issue 13, 1: the emulator killed between two answers; `record` then read the lost port.
    emulator = subprocess.Popen(
        [sys.executable, "-m", "servant_tui", "emulate-servo", "--protocol", "maestro"],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert emulator.stdout is not None
    found = re.search(r" on (\S+);", emulator.stdout.readline())
    assert found is not None
    records = tmp_path / "records.json"
    argv = ["--port", found.group(1), "--records", str(records), "--iterations", "20"]
    argv += ["--learner", str(tmp_path / "learner.npz")]
    teach = subprocess.Popen(
        [sys.executable, "-m", "servant_tui", "teach", *argv],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert teach.stdout is not None and teach.stdin is not None
        assert "The arm is armed on" in teach.stdout.readline()
    finally:
        emulator.kill()
        emulator.wait()
    out, err = teach.communicate("coffee\nrecord 0.2\n20\n\ncoffee\n", timeout=60)
    assert "Traceback" not in err, err
    assert teach.returncode == 0, err
    lost = [line for line in out.splitlines() if "the arm is disarmed" in line]
    assert len(lost) == 1 and "was lost" in lost[0], out
    assert [(r.scene, r.pose) for r in load_records(records)] == [("coffee", {"shoulder": 20.0})]


def test_teach_records_do_not_grow_with_the_labels_taught_before(monkeypatch, capsys):
    # Issue 13, 8: each typed record listed every scene taught before it (a zero score each), so
    # the file grew quadratically with the labels of a session (300 labels: 116 s).
    labels = [f"scene{i}" for i in range(40)]
    session = "".join(f"{label}\n{i}\n" for i, label in enumerate(labels)) + "\n"
    status, _, _ = run(["teach", "--iterations", "1"], session, monkeypatch, capsys)
    assert status == 0
    records = load_records()
    assert [r.scene for r in records] == labels
    assert all(set(r.scores["acoustic"]) == {r.scene} for r in records)


def test_servo_query_refuses_an_oversized_firmata_reply_in_one_line(monkeypatch, capsys):
    # Issue 13, 2: a pin state reply of 200 data bytes ended `servo query` in an OverflowError.
    emulator, port = start_emulator("firmata")
    try:
        emulator.pin_states[default_joints()[0].channel] = (1 << 1400) - 1  # 200 7-bit bytes
        argv = ["servo", "query", "--port", port, "--protocol", "firmata"]
        status, _, err = run(argv, "", monkeypatch, capsys)
    finally:
        emulator.stop()
    assert status == 2
    assert err.count("\n") == 1 and "not a Arduino (StandardFirmata) reply" in err
    assert "a pin state of 200 bytes" in err


def test_teach_with_an_arm_of_no_joints_is_one_line(tmp_path, monkeypatch, capsys):
    # Issue 13, 8: `"joints": []` ended `servant teach` in an IndexError.
    settings = tmp_path / "settings.json"
    settings.write_text('{"joints": []}')
    status, _, err = run(
        ["teach", "--settings", str(settings)], "coffee\n1\n\n", monkeypatch, capsys
    )
    assert status == 2 and err.count("\n") == 1
    assert "the arm needs at least one joint" in err


@pytest.mark.timeout(60)
@pytest.mark.parametrize("timeout", ["nan", "inf", "0", "-1", "1e9"])
def test_servo_query_refuses_a_timeout_that_would_hang(timeout, capsys):
    # Issue 13, 7: `--timeout nan` made a deadline that never comes; a silent controller hung.
    emulator, port = start_emulator("maestro", fault="silent")
    try:
        with pytest.raises(SystemExit) as info:
            main(["servo", "query", "--port", port, "--timeout", timeout])
    finally:
        emulator.stop()
    assert info.value.code == 2
    assert "argument --timeout" in capsys.readouterr().err


@pytest.mark.devices
def test_teach_dry_run_refuses_recordings_that_never_end(tmp_path):
    # Issue 13, 7: `record nan` looped for ever, growing memory; `record 1e9` died in
    # MemoryError. Run in a child process with bounded memory and time, so a regression fails
    # instead of taking the machine down.
    script = "coffee\nrecord nan\nrecord 1e9\nrecord inf\nrecord 0.3\n\n"
    limit = "import resource; resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30)); "
    code = limit + "from servant_tui.main import main; raise SystemExit(main())"
    argv = ["teach", "--dry-run", "--iterations", "5", "--records", str(tmp_path / "r.json")]
    argv += ["--learner", str(tmp_path / "l.npz")]
    proc = subprocess.run(
        [sys.executable, "-c", code, *argv],
        input=script,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.count("a recording must be 0 to 600 seconds") == 3
    assert "Recording for 0.3 s" in proc.stdout
    assert [r.source for r in load_records(tmp_path / "r.json")] == ["recorded"]


@pytest.mark.parametrize(
    ("option", "what"), [("--records", "teach records"), ("--learner", "action learner")]
)
def test_teach_files_that_cannot_be_saved_are_one_line(option, what, monkeypatch, capsys):
    # Issue 13, 6 (on the arm's side): nowhere to write ended in a traceback. /proc takes no new
    # files, even for root (a read-only folder would not stop root).
    argv = ["teach", "--iterations", "2", option, "/proc/servant-nowhere/file"]
    status, _, err = run(argv, "coffee\n1\n\n", monkeypatch, capsys)
    assert status == 2 and err.count("\n") == 1
    assert f"cannot save the {what} (No such file or directory)" in err


@pytest.mark.devices
def test_emulate_servo_prints_a_line_per_move_it_receives(tmp_path, monkeypatch, capsys):
    """Issue 22 item 9: the emulator's terminal says what it was sent, once per move (the link
    sends a rate-limited move as many small targets)."""
    emulator, port = serve("emulate-servo", "--seconds", "60")
    try:
        assert emulator.stdout is not None
        status, out, _ = run(
            ["servo", "move", "--port", port, "shoulder=40", "elbow=30"],
            "",
            monkeypatch,
            capsys,
        )
        assert status == 0, out
        move = emulator.stdout.readline()  # arming (every joint home), then the pose
    finally:
        emulator.terminate()
        emulator.wait(timeout=30)
    shoulder, elbow, gripper = default_joints()
    assert move.strip() == (
        f"received a move: shoulder 40° (channel {shoulder.channel}, 1222 µs), "
        f"elbow 30° (channel {elbow.channel}, 1167 µs), "
        f"gripper 0° (channel {gripper.channel}, 1000 µs)"
    )


@pytest.mark.devices
@pytest.mark.parametrize("stdin", ["/dev/zero", "long"])
def test_an_endless_or_overlong_answer_is_one_line(stdin, tmp_path):
    """`servant teach < /dev/zero` read one endless line until memory ran out (4.5 GB in 10 s),
    and a 20 MB label was taught into the records. In a child with bounded memory and time."""
    limit = "import resource; resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30)); "
    code = limit + "from servant_tui.main import main; raise SystemExit(main())"
    argv = ["teach", "--records", str(tmp_path / "r.json"), "--learner", str(tmp_path / "l.npz")]
    if stdin == "long":
        source = tmp_path / "long.txt"
        source.write_text("coffee" * 400_000 + "\n42\n\n")
    else:
        source = stdin
    with open(source, "rb") as answers:
        proc = subprocess.run(
            [sys.executable, "-c", code, *argv],
            stdin=answers,
            capture_output=True,
            timeout=60,
        )
    err = proc.stderr.decode()
    assert proc.returncode == 2, err[-2000:]
    assert err.startswith("servant: error: teach: an answer longer than 1000 characters")
    assert err.count("\n") == 1
    assert not (tmp_path / "r.json").exists()
