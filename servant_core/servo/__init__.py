"""The arm's servo controllers: protocol encoders, calibration, the serial link and an emulator."""

from __future__ import annotations

from servant_core.errors import ServantError
from servant_core.servo.base import Move, ProtocolError, ServoProtocol
from servant_core.servo.firmata import Firmata
from servant_core.servo.maestro import Maestro
from servant_core.servo.ssc32 import SSC32

PROTOCOLS: dict[str, type[ServoProtocol]] = {p.name: p for p in (Maestro, SSC32, Firmata)}


def protocol_for(name: str) -> ServoProtocol:
    try:
        return PROTOCOLS[name]()
    except KeyError:
        raise ServantError(
            f"servo protocol {name!r} is unknown; use one of {', '.join(PROTOCOLS)}"
        ) from None


__all__ = ["PROTOCOLS", "Move", "ProtocolError", "ServoProtocol", "protocol_for"]
