"""What every servo protocol offers the link: pure byte encoders and reply parsers.

A protocol works in pulse widths (microseconds) on channels; angles and limits are the link's
business (see `calibration`). Reply parsers take the bytes read so far and return
`(value, bytes consumed)`, or None when more bytes are needed; bytes that cannot be a reply raise
`ProtocolError`, which the link reports as a controller sending garbage.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar, Protocol

from servant_core.settings import Joint


class ProtocolError(ValueError):
    """Bytes from the controller that are not a valid reply."""


@dataclass(frozen=True)
class Move:
    """One channel's part of a command: go to `pulse_us`, no faster than `speed_us_s` (if given)."""

    channel: int
    pulse_us: float
    speed_us_s: float | None = None


def pulse_speed(joint: Joint) -> float:
    """The joint's maximum speed in microseconds of pulse width per second."""
    us_per_degree = (joint.max_pulse_us - joint.min_pulse_us) / (joint.max_angle - joint.min_angle)
    return joint.max_speed_deg_s * us_per_degree


class ServoProtocol(Protocol):
    name: ClassVar[str]
    title: ClassVar[str]  # the controller, for messages: "Pololu Maestro"
    baudrate: ClassVar[int]

    def check_joints(self, joints: Sequence[Joint]) -> list[str]:
        """Why these joints cannot be driven with this protocol (empty when they can)."""
        ...

    def probe(self) -> bytes:
        """A request every healthy controller answers: how the link knows one is there."""
        ...

    def parse_probe(self, buffer: bytes) -> tuple[str, int] | None:
        """The controller's answer to `probe`, described in words."""
        ...

    def setup(self, joints: Sequence[Joint]) -> bytes:
        """Bytes sent once after connecting: pin modes, hardware speed and pulse limits."""
        ...

    def move(self, moves: Sequence[Move]) -> bytes:
        """One command moving all `moves` together."""
        ...

    def query(self, channels: Sequence[int]) -> bytes:
        """A request for the pulse width each channel is sending."""
        ...

    def parse_positions(
        self, buffer: bytes, channels: Sequence[int]
    ) -> tuple[list[float | None], int] | None:
        """Pulse widths (us) per channel; None for a channel that sends no pulse yet."""
        ...
