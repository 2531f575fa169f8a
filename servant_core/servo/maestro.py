"""Pololu Maestro, compact protocol (Maestro user's guide, "Serial Servo Commands").

Targets are in quarter-microseconds, sent as two 7-bit data bytes (low bits first). Speeds are in
0.25 us per 10 ms, accelerations in 0.25 us per 10 ms per 80 ms; 0 means "no limit" for both.
Replies are plain little-endian 16-bit values.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

from servant_core.servo.base import Move, ProtocolError, pulse_speed
from servant_core.settings import Joint

SET_TARGET = 0x84
SET_SPEED = 0x87
SET_ACCELERATION = 0x89
GET_POSITION = 0x90
GET_ERRORS = 0xA1
MAX_VALUE = 0x3FFF  # two 7-bit data bytes
ERROR_BITS = 9  # bits 0-8 are defined (serial signal ... script program counter)


def _seven_bit_pair(value: int) -> bytes:
    if not 0 <= value <= MAX_VALUE:
        raise ValueError(f"{value} does not fit in two 7-bit bytes")
    return bytes((value & 0x7F, (value >> 7) & 0x7F))


def _channel(channel: int) -> int:
    if not 0 <= channel <= 0x7F:
        raise ValueError(f"channel {channel} is not 0..127")
    return channel


def set_target(channel: int, pulse_us: float) -> bytes:
    return bytes((SET_TARGET, _channel(channel))) + _seven_bit_pair(round(pulse_us * 4))


def set_speed(channel: int, speed: int) -> bytes:
    return bytes((SET_SPEED, _channel(channel))) + _seven_bit_pair(speed)


def set_acceleration(channel: int, acceleration: int) -> bytes:
    if not 0 <= acceleration <= 255:
        raise ValueError(f"acceleration {acceleration} is not 0..255")
    return bytes((SET_ACCELERATION, _channel(channel))) + _seven_bit_pair(acceleration)


def get_position(channel: int) -> bytes:
    return bytes((GET_POSITION, _channel(channel)))


def get_errors() -> bytes:
    return bytes((GET_ERRORS,))


def speed_units(us_per_s: float) -> int:
    """Maestro speed units for a limit of `us_per_s`, rounded down and never 0 (0 = unlimited)."""
    return max(1, min(MAX_VALUE, math.floor(us_per_s / 25)))


def encode_word(value: int) -> bytes:
    """A 16-bit reply (position or error bits), as the Maestro sends it."""
    return int(value).to_bytes(2, "little")


def decode_word(reply: bytes) -> int:
    return int.from_bytes(reply[:2], "little")


class Maestro:
    name: ClassVar[str] = "maestro"
    title: ClassVar[str] = "Pololu Maestro"
    baudrate: ClassVar[int] = 9600

    def check_joints(self, joints: Sequence[Joint]) -> list[str]:
        return [f"joint {j.name!r}: Maestro channels are 0..23" for j in joints if j.channel > 23]

    def probe(self) -> bytes:
        return get_errors()

    def parse_probe(self, buffer: bytes) -> tuple[str, int] | None:
        if len(buffer) < 2:
            return None
        errors = decode_word(buffer)
        if errors >> ERROR_BITS:
            raise ProtocolError(f"error bits 0x{errors:04x} are not Maestro errors")
        return (f"Pololu Maestro, error bits 0x{errors:04x}", 2)

    def setup(self, joints: Sequence[Joint]) -> bytes:
        return b"".join(set_speed(j.channel, speed_units(pulse_speed(j))) for j in joints)

    def move(self, moves: Sequence[Move]) -> bytes:
        return b"".join(set_target(m.channel, m.pulse_us) for m in moves)

    def query(self, channels: Sequence[int]) -> bytes:
        return b"".join(get_position(c) for c in channels)

    def parse_positions(
        self, buffer: bytes, channels: Sequence[int]
    ) -> tuple[list[float | None], int] | None:
        size = 2 * len(channels)
        if len(buffer) < size:
            return None
        pulses: list[float | None] = []
        for i in range(len(channels)):
            value = decode_word(buffer[2 * i : 2 * i + 2])
            if value > MAX_VALUE:
                raise ProtocolError(f"position {value} is beyond what a Maestro can send")
            pulses.append(value / 4 if value else None)
        return pulses, size
