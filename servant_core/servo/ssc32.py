"""Lynxmotion SSC-32, ASCII protocol (SSC-32 user's manual).

`#<ch>P<pw>S<spd>T<time>\\r`: pulse width in us, speed in us per second, time in ms. Several
channels in one command form a group move: they start and end together. `Q\\r` answers `.`
(done) or `+` (moving); `QP<ch>\\r` answers one byte per channel, the pulse width / 10.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

from servant_core.servo.base import Move, ProtocolError
from servant_core.settings import Joint

MIN_PULSE_US = 500
MAX_PULSE_US = 2500
VERSION_PREFIX = b"SSC32"
MAX_LINE = 64


def move_command(moves: Sequence[Move], time_ms: int | None = None) -> bytes:
    parts = []
    for m in moves:
        pulse = round(m.pulse_us)
        if not MIN_PULSE_US <= pulse <= MAX_PULSE_US:
            raise ValueError(
                f"pulse {pulse} us is outside the SSC-32's {MIN_PULSE_US}..{MAX_PULSE_US}"
            )
        part = f"#{m.channel}P{pulse}"
        if m.speed_us_s is not None:
            part += f"S{max(1, math.floor(m.speed_us_s))}"  # rounded down: never faster
        parts.append(part)
    if time_ms is not None:
        parts.append(f"T{time_ms}")
    return ("".join(parts) + "\r").encode("ascii")


def query_movement() -> bytes:
    return b"Q\r"


def query_pulse(channels: Sequence[int]) -> bytes:
    return ("".join(f"QP{c}" for c in channels) + "\r").encode("ascii")


def version_query() -> bytes:
    return b"VER\r"


def encode_pulse_byte(pulse_us: float) -> int:
    return max(0, min(255, round(pulse_us / 10)))


class SSC32:
    name: ClassVar[str] = "ssc32"
    title: ClassVar[str] = "Lynxmotion SSC-32"
    baudrate: ClassVar[int] = 115200

    def check_joints(self, joints: Sequence[Joint]) -> list[str]:
        lines = [f"joint {j.name!r}: SSC-32 channels are 0..31" for j in joints if j.channel > 31]
        lines += [
            f"joint {j.name!r}: the SSC-32 sends {MIN_PULSE_US}..{MAX_PULSE_US} us pulses only"
            for j in joints
            if j.min_pulse_us < MIN_PULSE_US or j.max_pulse_us > MAX_PULSE_US
        ]
        return lines

    def probe(self) -> bytes:
        return version_query()

    def parse_probe(self, buffer: bytes) -> tuple[str, int] | None:
        end = buffer.find(b"\r")
        if end < 0:
            if len(buffer) > MAX_LINE:
                raise ProtocolError("no end of line in the version reply")
            return None
        line = buffer[:end]
        if (
            not line.startswith(VERSION_PREFIX)
            or not line.isascii()
            or not line.decode().isprintable()
        ):
            raise ProtocolError(f"{line[:20]!r} is not an SSC-32 version")
        return line.decode(), end + 1

    def setup(self, joints: Sequence[Joint]) -> bytes:
        return b""  # the speed limit travels with every move

    def move(self, moves: Sequence[Move]) -> bytes:
        return move_command(moves)

    def query(self, channels: Sequence[int]) -> bytes:
        return query_pulse(channels)

    def parse_positions(
        self, buffer: bytes, channels: Sequence[int]
    ) -> tuple[list[float | None], int] | None:
        if len(buffer) < len(channels):
            return None
        pulses: list[float | None] = []
        for value in buffer[: len(channels)]:
            if value and not MIN_PULSE_US // 10 <= value <= MAX_PULSE_US // 10:
                raise ProtocolError(f"pulse byte {value} is not an SSC-32 pulse width")
            pulses.append(value * 10.0 if value else None)
        return pulses, len(channels)
