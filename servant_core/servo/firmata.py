"""Firmata, for an Arduino running StandardFirmata (Firmata protocol 2.x).

Servo pins are configured with `SERVO_CONFIG` (`F0 70 pin min max F7`), which also sets their
mode and makes the Arduino's Servo library clamp every pulse to [min, max]. Positions are written
as analog messages (`E0|pin`, pins 0-15) or extended analog (`F0 6F`, any pin), always in
microseconds: joints below 544 us are refused. Firmata has no speed limit: the link's rate
limiting is the only one. A pin state query reads a position back: the last value written.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

from servant_core.servo.base import Move, ProtocolError
from servant_core.settings import Joint

ANALOG_MESSAGE = 0xE0
DIGITAL_MESSAGE = 0x90
REPORT_VERSION = 0xF9
SET_PIN_MODE = 0xF4
START_SYSEX = 0xF0
END_SYSEX = 0xF7
SERVO_CONFIG = 0x70
EXTENDED_ANALOG = 0x6F
PIN_STATE_QUERY = 0x6D
PIN_STATE_RESPONSE = 0x6E
PIN_MODE_SERVO = 0x04
SERVO_MICROSECONDS_FROM = 544  # StandardFirmata: below this a servo value is an angle
MAX_PIN = 127
MAX_STATE_BYTES = 3  # StandardFirmata sends a pin's 16-bit state in at most three 7-bit bytes


def seven_bit(value: int, count: int = 2) -> bytes:
    """`value` as `count` 7-bit bytes, least significant first."""
    if not 0 <= value < 1 << (7 * count):
        raise ValueError(f"{value} does not fit in {count} 7-bit bytes")
    return bytes((value >> (7 * i)) & 0x7F for i in range(count))


def _pin(pin: int) -> int:
    if not 0 <= pin <= MAX_PIN:
        raise ValueError(f"pin {pin} is not 0..{MAX_PIN}")
    return pin


def set_pin_mode(pin: int, mode: int) -> bytes:
    return bytes((SET_PIN_MODE, _pin(pin), mode))


def servo_config(pin: int, min_pulse_us: int, max_pulse_us: int) -> bytes:
    return (
        bytes((START_SYSEX, SERVO_CONFIG, _pin(pin)))
        + seven_bit(min_pulse_us)
        + seven_bit(max_pulse_us)
        + bytes((END_SYSEX,))
    )


def analog_write(pin: int, value: int) -> bytes:
    """Pins 0-15 with 14 bits fit an analog message; anything else goes as extended analog."""
    if pin <= 15 and value < 1 << 14:
        return bytes((ANALOG_MESSAGE | pin,)) + seven_bit(value)
    return extended_analog(pin, value)


def extended_analog(pin: int, value: int) -> bytes:
    count = max(2, (value.bit_length() + 6) // 7)
    return (
        bytes((START_SYSEX, EXTENDED_ANALOG, _pin(pin)))
        + seven_bit(value, count)
        + bytes((END_SYSEX,))
    )


def report_version() -> bytes:
    return bytes((REPORT_VERSION,))


def pin_state_query(pin: int) -> bytes:
    return bytes((START_SYSEX, PIN_STATE_QUERY, _pin(pin), END_SYSEX))


def pin_state_response(pin: int, mode: int, state: int) -> bytes:
    count = max(1, (state.bit_length() + 6) // 7)
    return (
        bytes((START_SYSEX, PIN_STATE_RESPONSE, pin, mode))
        + seven_bit(state, count)
        + bytes((END_SYSEX,))
    )


def from_seven_bit(data: bytes) -> int:
    return sum(b << (7 * i) for i, b in enumerate(data))


def next_message(buffer: bytes) -> tuple[bytes, int] | None:
    """The first complete Firmata message in `buffer` and its length; None if it is incomplete."""
    if not buffer:
        return None
    command = buffer[0]
    if command < 0x80:
        raise ProtocolError(f"data byte 0x{command:02x} where a Firmata command was expected")
    if command == START_SYSEX:
        end = buffer.find(bytes((END_SYSEX,)))
        if end < 0:
            return None
        body = buffer[1:end]
        if any(b >= 0x80 for b in body):
            raise ProtocolError("command byte inside a Firmata sysex message")
        return buffer[: end + 1], end + 1
    # Analog and digital messages carry a pin or port in their low nibble; all have 2 data bytes.
    if (command & 0xF0) in (ANALOG_MESSAGE, DIGITAL_MESSAGE) or command == REPORT_VERSION:
        if len(buffer) < 3:
            return None
        if buffer[1] >= 0x80 or buffer[2] >= 0x80:
            raise ProtocolError("command byte inside a Firmata message")
        return buffer[:3], 3
    raise ProtocolError(f"0x{command:02x} is not a Firmata message StandardFirmata sends")


class Firmata:
    name: ClassVar[str] = "firmata"
    title: ClassVar[str] = "Arduino (StandardFirmata)"
    baudrate: ClassVar[int] = 57600

    def check_joints(self, joints: Sequence[Joint]) -> list[str]:
        return [
            f"joint {j.name!r}: StandardFirmata reads pulses below "
            f"{SERVO_MICROSECONDS_FROM} us as angles; raise min_pulse_us"
            for j in joints
            if j.min_pulse_us < SERVO_MICROSECONDS_FROM
        ]

    def _find(self, buffer: bytes, wanted) -> tuple[bytes, int] | None:
        """The first message `wanted` accepts, skipping others (StandardFirmata reports freely)."""
        offset = 0
        while (found := next_message(buffer[offset:])) is not None:
            message, size = found
            offset += size
            if wanted(message):
                return message, offset
        return None

    def probe(self) -> bytes:
        return report_version()

    def parse_probe(self, buffer: bytes) -> tuple[str, int] | None:
        found = self._find(buffer, lambda m: m[0] == REPORT_VERSION)
        if found is None:
            return None
        message, used = found
        return f"Firmata protocol {message[1]}.{message[2]}", used

    def setup(self, joints: Sequence[Joint]) -> bytes:
        return b"".join(
            set_pin_mode(j.channel, PIN_MODE_SERVO)
            + servo_config(j.channel, round(j.min_pulse_us), round(j.max_pulse_us))
            for j in joints
        )

    def move(self, moves: Sequence[Move]) -> bytes:
        return b"".join(analog_write(m.channel, round(m.pulse_us)) for m in moves)

    def query(self, channels: Sequence[int]) -> bytes:
        return b"".join(pin_state_query(c) for c in channels)

    def parse_positions(
        self, buffer: bytes, channels: Sequence[int]
    ) -> tuple[list[float | None], int] | None:
        pulses: list[float | None] = []
        used = 0
        for channel in channels:
            found = self._find(
                buffer[used:],
                lambda m, c=channel: len(m) >= 5 and m[1] == PIN_STATE_RESPONSE and m[2] == c,
            )
            if found is None:
                return None
            message, size = found
            used += size
            data = message[4:-1]
            if len(data) > MAX_STATE_BYTES:
                raise ProtocolError(
                    f"a pin state of {len(data)} bytes (StandardFirmata sends {MAX_STATE_BYTES})"
                )
            state = from_seven_bit(data)
            pulses.append(float(state) if state >= SERVO_MICROSECONDS_FROM else None)
        return pulses, used
