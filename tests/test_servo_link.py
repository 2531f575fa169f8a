"""The link's faults and safety rules, on the emulator's pty and in dry runs."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from servant_core.errors import ServantError
from servant_core.servo import maestro
from servant_core.servo.emulator import start_emulator
from servant_core.servo.link import MAX_STEP_S, ManualClock, ServoLink
from servant_core.settings import Joint, default_joints

JOINTS = default_joints()


@pytest.fixture
def emulator():
    emu, port = start_emulator("maestro")
    yield emu, port
    emu.stop()


def dry_link(protocol="maestro"):
    clock = ManualClock()
    return ServoLink.open(
        None, protocol, JOINTS, dry_run=True, clock=clock, sleep=clock.sleep
    ), clock


def test_unknown_protocol_is_one_clear_error():
    with pytest.raises(
        ServantError, match="protocol 'lx16a' is unknown; use one of maestro, ssc32, firmata"
    ):
        ServoLink.open("/dev/ttyUSB0", "lx16a", JOINTS)


def test_missing_port(tmp_path):
    with pytest.raises(ServantError, match="no such serial port"):
        ServoLink.open(str(tmp_path / "ttyACM9"), "maestro", JOINTS)
    with pytest.raises(ServantError, match="no serial port given"):
        ServoLink.open(None, "maestro", JOINTS)


def test_busy_port(emulator):
    _, port = emulator
    with ServoLink.open(port, "maestro", JOINTS):
        with pytest.raises(ServantError, match="busy"):
            ServoLink.open(port, "maestro", JOINTS)


def test_controller_that_does_not_answer_times_out():
    emu, port = start_emulator("ssc32", fault="silent")
    try:
        with pytest.raises(ServantError, match=r"no answer from a Lynxmotion SSC-32 within 0.2 s"):
            ServoLink.open(port, "ssc32", JOINTS, timeout=0.2)
    finally:
        emu.stop()


def test_garbage_from_the_controller_is_reported_and_survived(emulator):
    emu, port = emulator
    emu.fault = "garbage"
    with pytest.raises(ServantError, match="not a Pololu Maestro reply"):
        ServoLink.open(port, "maestro", JOINTS)
    emu.fault = None
    with ServoLink.open(port, "maestro", JOINTS) as link:
        emu.fault = "garbage"
        with pytest.raises(ServantError, match="not a Pololu Maestro reply"):
            link.read_positions()
        emu.fault = None
        assert link.read_positions() == {}  # no channel sends a pulse yet; the link still works


def test_wrong_protocol_on_the_line_is_garbage_or_silence():
    emu, port = start_emulator("ssc32")
    try:
        with pytest.raises(ServantError, match="no answer|not a Arduino|not a"):
            ServoLink.open(port, "firmata", JOINTS, timeout=0.2)
    finally:
        emu.stop()


def test_nothing_moves_unless_armed():
    link, _ = dry_link()
    setup = list(link.sent)
    with pytest.raises(ServantError, match="not armed"):
        link.move_to({"shoulder": 10})
    assert list(link.sent) == setup
    link.arm()
    link.disarm()
    sent = len(link.sent)
    assert link.step() == {}
    assert len(link.sent) == sent


def test_dry_run_shows_the_exact_bytes():
    link, clock = dry_link()
    # Setup: each joint's speed limit (shoulder 30 deg/s = 166.7 us/s -> 6 units of 25 us/s).
    assert link.sent[0] == maestro.set_speed(3, 6) + maestro.set_speed(4, 10) + maestro.set_speed(
        5, 13
    )
    link.arm()  # no pulse known: every joint goes home
    assert link.sent[-1] == maestro.set_target(3, 1000) + maestro.set_target(
        4, 1500
    ) + maestro.set_target(5, 1000)
    clock.sleep(0.1)
    assert link.move_to({"shoulder": 90}, wait=False) == {"shoulder": 3.0}  # 30 deg/s for 0.1 s
    assert link.sent[-1] == maestro.set_target(3, 1000 + 3 * 500 / 90)


def test_angles_are_clamped_and_said_and_unknown_joints_refused():
    link, clock = dry_link()
    link.arm()
    link.move_to({"elbow": 500, "gripper": -20}, wait=False)
    assert link.goal == {"elbow": 135.0, "gripper": 0.0}
    assert link.notes == [
        "elbow: 500 is beyond 0..135 degrees, clamped to 135",
        "gripper: -20 is beyond 0..90 degrees, clamped to 0",
    ]
    with pytest.raises(
        ServantError, match="no joint named 'wrist'; the arm's joints are: shoulder, elbow, gripper"
    ):
        link.move_to({"wrist": 10})
    with pytest.raises(ServantError, match="not an angle"):
        link.move_to({"elbow": float("nan")})
    assert link.goal == {"elbow": 135.0, "gripper": 0.0}


def test_rate_limit_never_jumps_after_a_pause():
    link, clock = dry_link()
    link.arm()
    clock.sleep(60)  # a long pause must not turn into one big step
    first = link.move_to({"shoulder": 90}, wait=False)
    assert first == {"shoulder": pytest.approx(30 * MAX_STEP_S)}
    clock.sleep(0.05)
    assert link.step() == {"shoulder": pytest.approx(30 * MAX_STEP_S + 1.5)}
    assert link.settle()["shoulder"] == 90.0
    assert link.status().angles["shoulder"] == 90.0


def test_a_step_finer_than_the_pulse_resolution_sends_no_second_command():
    """CI saw the café's last pose sent twice: a step of a few thousandths of a degree (or none, two
    steps at one clock reading) encodes to the quarter microsecond just sent. Only new commands go
    out; arming again sends the pose again whatever was sent before."""
    link, clock = dry_link()
    link.arm()
    clock.sleep(0.1)
    link.move_to({"shoulder": 3.0}, wait=False)  # reached in one step
    sent = len(link.sent)
    link.goal["shoulder"] = 3.0001  # 0.0006 us further: the same quarter microsecond
    clock.sleep(0.1)
    link.step()
    link.step()  # no time passed
    assert len(link.sent) == sent
    assert link.commanded["shoulder"] == 3.0001
    link.goal["shoulder"] = 4.0
    clock.sleep(0.1)
    link.step()
    assert len(link.sent) == sent + 1
    link.disarm()
    link.arm()
    assert len(link.sent) == sent + 1  # every joint's pulse is known: arming sends nothing
    clock.sleep(0.1)
    link.move_to({"shoulder": 4.0}, wait=False)
    assert len(link.sent) == sent + 2  # a move after arming is always said


def test_link_loss_disarms_and_reconnects_when_the_port_comes_back(tmp_path):
    stable = tmp_path / "servo0"
    emu, port = start_emulator("maestro", link=stable)
    link = ServoLink.open(port, "maestro", JOINTS)
    try:
        link.arm()
        assert link.status().armed and link.status().connected
        emu.stop()
        with pytest.raises(ServantError, match="was lost.*the arm is disarmed"):
            link.move_to({"shoulder": 10})
        state = link.status()
        assert not state.armed and not state.connected
        emu, _ = start_emulator("maestro", link=stable)
        assert link.reconnect()
        assert link.connected and not link.armed  # back, but only the user re-arms it
        link.arm()
        link.move_to({"shoulder": 1})
    finally:
        link.close()
        emu.stop()


def test_a_blocking_move_stops_when_disarmed():
    link, clock = dry_link()
    link.arm()

    def sleep(seconds):
        clock.sleep(seconds)
        if clock() > 1.0:
            link.disarm()  # as the user (or a lost port) would, from another thread

    link.sleep = sleep
    reached = link.move_to({"shoulder": 90})
    assert 25 < reached["shoulder"] < 35  # about 1 s at 30 deg/s, then it stopped
    assert not link.armed


def test_joints_a_protocol_cannot_drive_are_refused_before_opening():
    low = [Joint("wrist", 3, 0, 90, 500, 1500, 30, 0)]
    with pytest.raises(ServantError, match="StandardFirmata reads pulses below 544"):
        ServoLink.open(None, "firmata", low, dry_run=True)


def _emulator_process(protocol: str) -> tuple[subprocess.Popen, str]:
    """`servant emulate-servo` in its own process, and its port: killing it unplugs for real."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "servant_tui", "emulate-servo", "--protocol", protocol],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    port = re.search(r" on (\S+);", proc.stdout.readline())
    assert port is not None
    return proc, port.group(1)


@pytest.mark.devices
@pytest.mark.parametrize("protocol", ["maestro", "ssc32", "firmata"])
def test_an_idle_controller_killed_disarms_the_link_with_one_clear_error(protocol):
    # Issue 13, 1: pyserial's reset_input_buffer raises termios.error (not an OSError) on a
    # pty whose other side is gone; it escaped raw and the link stayed armed.
    proc, port = _emulator_process(protocol)
    try:
        link = ServoLink.open(port, protocol, JOINTS, timeout=1.0)
        link.arm()
    finally:
        proc.kill()
        proc.wait()
    try:
        for call in (link.read_positions, link.arm, lambda: link.record(0.2)):
            with pytest.raises(ServantError, match="lost|not connected"):
                call()
            state = link.status()
            assert not state.armed and not state.connected
        with pytest.raises(ServantError, match="not armed"):
            link.move_to({"shoulder": 10})
    finally:
        link.close()


def test_an_emulator_stopped_while_idle_disarms_the_link():
    emu, port = start_emulator("maestro")
    link = ServoLink.open(port, "maestro", JOINTS)
    link.arm()
    emu.stop()
    with pytest.raises(ServantError, match=r"was lost \(.*\); the arm is disarmed"):
        link.read_positions()
    assert not link.armed and not link.connected
    link.close()


def test_a_file_that_is_not_a_serial_port_is_said(tmp_path):
    for port in ("/dev/null", str(tmp_path)):
        with pytest.raises(ServantError, match="not a serial port"):
            ServoLink.open(port, "maestro", JOINTS)


def test_an_emulator_link_that_cannot_be_made_is_one_clear_error(tmp_path):
    with pytest.raises(ServantError, match="cannot make it a link to the emulator's port"):
        start_emulator("maestro", link=tmp_path / "no-such-folder" / "servo0")
