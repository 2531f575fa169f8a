"""Byte-exact encoders and decoders, against the vendors' documented examples."""

from __future__ import annotations

import pytest

from servant_core.errors import ServantError
from servant_core.servo import ProtocolError, firmata, maestro, protocol_for, ssc32
from servant_core.servo.base import Move
from servant_core.settings import Joint

CH = [0]


def test_maestro_set_target_matches_the_users_guide():
    # Maestro user's guide: channel 2 to 1500 us (6000 quarter-us) is 0x84, 0x02, 0x70, 0x2E.
    assert maestro.set_target(2, 1500) == bytes([0x84, 0x02, 0x70, 0x2E])
    assert maestro.set_target(0, 1000.1) == bytes([0x84, 0x00, 0x20, 0x1F])  # 4000 quarter-us


def test_maestro_speed_acceleration_and_queries():
    assert maestro.set_speed(5, 140) == bytes([0x87, 0x05, 0x0C, 0x01])
    assert maestro.set_acceleration(5, 4) == bytes([0x89, 0x05, 0x04, 0x00])
    assert maestro.get_position(2) == bytes([0x90, 0x02])
    assert maestro.get_errors() == bytes([0xA1])
    with pytest.raises(ValueError):
        maestro.set_acceleration(0, 256)


def test_maestro_speed_units_never_round_to_unlimited():
    assert maestro.speed_units(1000) == 40  # 40 x 0.25 us / 10 ms = 1000 us/s
    assert maestro.speed_units(1049) == 41  # rounded down: never faster than asked
    assert maestro.speed_units(1) == 1  # 0 would mean "no limit"


def test_maestro_replies():
    m = maestro.Maestro()
    # The guide: a position of 1500 us is answered 0x70, 0x17 (6000, low byte first).
    assert m.parse_positions(bytes([0x70, 0x17]), CH) == ([1500.0], 2)
    assert m.parse_positions(bytes([0x70]), CH) is None
    assert m.parse_positions(bytes([0, 0]), CH) == ([None], 2)  # channel off
    assert m.parse_probe(bytes([0x10, 0x00]))[1] == 2
    with pytest.raises(ProtocolError):
        m.parse_probe(bytes([0xFF, 0xFF]))
    with pytest.raises(ProtocolError):
        m.parse_positions(bytes([0xFF, 0xFF]), CH)


def test_ssc32_moves_match_the_manual():
    # SSC-32 manual: "#5 P1600 S750 <cr>" and the group move "#5 P1600 #10 P750 T2500 <cr>".
    assert ssc32.move_command([Move(5, 1600, 750)]) == b"#5P1600S750\r"
    assert (
        ssc32.move_command([Move(5, 1600), Move(10, 750)], time_ms=2500) == b"#5P1600#10P750T2500\r"
    )
    assert ssc32.move_command([Move(0, 1500.4, 166.9)]) == b"#0P1500S166\r"
    assert ssc32.query_pulse([5]) == b"QP5\r"
    assert ssc32.query_movement() == b"Q\r"
    with pytest.raises(ValueError):
        ssc32.move_command([Move(0, 2600)])


def test_ssc32_replies():
    s = ssc32.SSC32()
    assert s.parse_positions(bytes([150, 0]), [5, 6]) == ([1500.0, None], 2)
    assert s.parse_probe(b"SSC32-V2.50USB\r") == ("SSC32-V2.50USB", 15)
    assert s.parse_probe(b"SSC32-V2") is None
    with pytest.raises(ProtocolError):
        s.parse_positions(bytes([3]), [5])
    with pytest.raises(ProtocolError):
        s.parse_probe(b"\xff\xfe garbage\r")


def test_firmata_messages():
    assert firmata.set_pin_mode(9, firmata.PIN_MODE_SERVO) == bytes([0xF4, 0x09, 0x04])
    # Servo config: F0 70 pin minLSB minMSB maxLSB maxMSB F7; 544 = 0x220, 2400 = 0x960.
    assert firmata.servo_config(9, 544, 2400) == bytes(
        [0xF0, 0x70, 0x09, 0x20, 0x04, 0x60, 0x12, 0xF7]
    )
    assert firmata.analog_write(9, 1500) == bytes([0xE9, 0x5C, 0x0B])  # 1500 = 0x5DC
    assert firmata.analog_write(20, 1500) == bytes([0xF0, 0x6F, 0x14, 0x5C, 0x0B, 0xF7])
    assert firmata.report_version() == bytes([0xF9])
    assert firmata.pin_state_query(9) == bytes([0xF0, 0x6D, 0x09, 0xF7])


def test_firmata_replies_skip_unsolicited_reports():
    f = firmata.Firmata()
    analog_report = bytes([0xE0, 0x01, 0x02])
    reply = analog_report + firmata.pin_state_response(9, 4, 1500)
    assert f.parse_positions(reply, [9]) == ([1500.0], len(reply))
    assert f.parse_positions(reply[:-1], [9]) is None
    firmware = bytes([0xF0, 0x79, 2, 5]) + b"S\x00F\x00" + bytes([0xF7])
    assert f.parse_probe(firmware + bytes([0xF9, 2, 5])) == (
        "Firmata protocol 2.5",
        len(firmware) + 3,
    )
    with pytest.raises(ProtocolError):
        f.parse_probe(bytes([0x13, 0x37]))


def test_firmata_pin_state_with_oversized_data_is_refused():
    # Issue 13, 2: 200 data bytes made a 1400-bit integer, and float() of it an OverflowError.
    reply = bytes([0xF0, 0x6E, 9, 4]) + bytes([0x7F] * 200) + bytes([0xF7])
    with pytest.raises(ProtocolError, match="a pin state of 200 bytes"):
        firmata.Firmata().parse_positions(reply, [9])
    largest = firmata.pin_state_response(9, 4, (1 << 16) - 1)
    assert firmata.Firmata().parse_positions(largest, [9]) == ([65535.0], len(largest))


def test_protocols_refuse_joints_they_cannot_drive():
    low = Joint("wrist", 3, 0, 90, 500, 1500, 30, 0)
    assert firmata.Firmata().check_joints([low])  # StandardFirmata would read 500 as degrees
    assert not maestro.Maestro().check_joints([low])
    assert ssc32.SSC32().check_joints([Joint("x", 40, 0, 90, 1000, 1500, 30, 0)])
    with pytest.raises(ServantError, match="unknown"):
        protocol_for("dynamixel")
