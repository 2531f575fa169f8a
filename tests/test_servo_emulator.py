"""The emulator over a real pty, driven through pyserial: set, move at speed, read back."""

from __future__ import annotations

import json
import signal

import pytest
import serial

from servant_core.servo import firmata, maestro, ssc32
from servant_core.servo.emulator import start_emulator
from servant_core.servo.link import ManualClock, ServoLink
from servant_core.settings import default_joints
from tests.conftest import servant, serve


@pytest.fixture
def clock():
    return ManualClock(100.0)


def _port(protocol, clock):
    emulator, port = start_emulator(protocol, clock=clock)
    handle = serial.Serial(port, 115200, timeout=1.0)
    yield emulator, handle
    handle.close()
    emulator.stop()


@pytest.fixture
def maestro_port(clock):
    yield from _port("maestro", clock)


@pytest.fixture
def ssc32_port(clock):
    yield from _port("ssc32", clock)


@pytest.fixture
def firmata_port(clock):
    yield from _port("firmata", clock)


def test_maestro_moves_at_the_set_speed(maestro_port, clock):
    _, port = maestro_port
    port.write(maestro.set_speed(0, 40) + maestro.set_target(0, 1000))  # 40 units: 1000 us/s
    port.write(maestro.set_target(0, 2000) + maestro.get_position(0))
    assert maestro.decode_word(port.read(2)) == 4000  # not moved yet: 1000 us
    clock.sleep(0.5)
    port.write(maestro.get_position(0))
    assert maestro.decode_word(port.read(2)) == 6000  # half way: 1500 us
    clock.sleep(1.0)
    port.write(maestro.get_position(0) + maestro.get_errors())
    assert maestro.decode_word(port.read(2)) == 8000
    assert port.read(2) == b"\x00\x00"


def test_maestro_reports_a_protocol_error_for_stray_bytes(maestro_port):
    _, port = maestro_port
    port.write(b"\x05\x06" + maestro.get_errors())
    assert maestro.decode_word(port.read(2)) == 1 << 4


def _sync(port):
    """A round trip: the emulator has handled every earlier byte before the test moves its clock."""
    port.write(b"Q\r")
    assert port.read(1) in (b"+", b".")


def test_ssc32_group_move_starts_and_ends_together(ssc32_port, clock):
    _, port = ssc32_port
    port.write(b"#0P1000#1P1000\r")
    port.write(ssc32.move_command([ssc32.Move(0, 2000), ssc32.Move(1, 1500)], time_ms=1000))
    _sync(port)
    clock.sleep(0.5)
    port.write(b"QP0QP1\rQ\r")
    assert port.read(3) == bytes([150, 125]) + b"+"
    clock.sleep(0.5)
    port.write(b"QP 0 QP 1\rQ\r")  # the manual's spelling, with spaces
    assert port.read(3) == bytes([200, 150]) + b"."


def test_ssc32_speed_limits_the_move(ssc32_port, clock):
    _, port = ssc32_port
    port.write(b"#3P1000\r#3P2000S500\r")
    _sync(port)
    clock.sleep(1.0)
    port.write(b"QP3\rVER\r")
    assert port.read(1) == bytes([150])
    assert port.read_until(b"\r") == b"SSC32-V2.50USB\r"


def test_firmata_servo_pin_reports_what_was_written(firmata_port):
    emulator, port = firmata_port
    port.write(firmata.report_version())
    assert port.read(3) == bytes([0xF9, 2, 5])
    port.write(firmata.set_pin_mode(20, 4) + firmata.servo_config(20, 1000, 2000))
    port.write(firmata.analog_write(20, 2400) + firmata.pin_state_query(20))
    assert port.read_until(bytes([0xF7])) == firmata.pin_state_response(20, 4, 2400)
    assert emulator.pulse(20) == 2000  # the Servo library clamps to the configured range


# Read-back resolution: Maestro 0.25 us, SSC-32 10 us, i.e. up to 0.05 and 1.8 degrees here.
@pytest.mark.parametrize(
    ("protocol", "resolution"), [("maestro", 0.05), ("ssc32", 1.8), ("firmata", 0.2)]
)
def test_link_moves_the_emulated_arm_and_reads_it_back(protocol, resolution, clock):
    emulator, port = start_emulator(protocol, clock=clock)
    links = []

    def sleep(seconds):
        links[
            0
        ].read_positions()  # a round trip, so the emulator has every command before time moves
        clock.sleep(seconds)

    try:
        with ServoLink.open(port, protocol, default_joints(), clock=clock, sleep=sleep) as link:
            links.append(link)
            assert link.arm() == {"shoulder": 0.0, "elbow": 90.0, "gripper": 0.0}
            start = clock()
            reached = link.move_to({"shoulder": 45, "gripper": 30})
            assert reached == {"shoulder": 45.0, "gripper": 30.0}
            # 45 degrees at 30 degrees/s: never sooner than 1.5 s.
            assert clock() - start >= 1.5
            sleep(1.0)  # the Maestro's own ramp (its speed rounded down) catches up
            angles = link.read_positions()
            assert angles == pytest.approx(
                {"shoulder": 45.0, "elbow": 90.0, "gripper": 30.0}, abs=resolution
            )
    finally:
        emulator.stop()


@pytest.mark.devices
@pytest.mark.parametrize("command", ["emulate-servo", "emulate-sensors"])
def test_list_ports_names_a_running_emulators_port_and_forgets_it_once_stopped(command):
    """Issue 39 item 13: `servant servo list-ports` listed /dev/ttyS0 but not the emulator's
    pseudo-terminal, which README step 1 tells the user to look for there."""
    proc, port = serve(command, "--seconds", "60")
    try:
        listed = json.loads(servant("servo", "list-ports", "--json").stdout)
        mine = [p for p in listed if p["port"] == port]
        assert len(mine) == 1 and f"servant {command}" in mine[0]["description"], listed
        plain = servant("servo", "list-ports").stdout
        assert port in plain and "No serial ports found" not in plain
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
    assert port not in servant("servo", "list-ports").stdout
