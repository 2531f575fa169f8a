"""A servo controller in software: Maestro, SSC-32 or StandardFirmata, on one side of a pty pair.

It parses what a real controller parses, moves each channel towards its target at the commanded
speed (by its own clock, so tests can step time), and answers queries as the real one does. The
link, the tests, the demo and anyone without hardware talk to it through the pty's other side,
with pyserial, exactly as they would talk to a USB controller.
"""

from __future__ import annotations

import os
import re
import select
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from servant_core.errors import ServantError
from servant_core.pty_port import PtyPort, PtyService
from servant_core.servo import PROTOCOLS, firmata, maestro, ssc32

FAULTS = (None, "silent", "garbage")
GARBAGE = b"\xff" * 8  # line noise, as a wrong baud rate gives; no protocol accepts it
SSC32_VERSION = b"SSC32-V2.50USB"
FIRMATA_VERSION = (2, 5)
FIRMATA_DEFAULT_PULSES = (544, 2400)  # the Arduino Servo library's defaults
HISTORY = 10_000  # targets kept for `history`: minutes of motion, bounded for long demo runs


@dataclass
class Channel:
    """One output: the pulse it sends now (None: no pulse yet), where it is heading, how fast."""

    pulse: float | None = None
    target: float | None = None
    speed: float = 0.0  # us per second; 0: jump at once
    since: float = 0.0  # clock time `pulse` was last brought up to date

    def update(self, now: float) -> None:
        if self.pulse is None or self.target is None or not self.speed:
            self.pulse = self.target
        else:
            reach = self.speed * max(0.0, now - self.since)
            self.pulse = min(max(self.target, self.pulse - reach), self.pulse + reach)
        self.since = now

    def aim(self, target: float | None, now: float, speed: float | None = None) -> None:
        self.update(now)
        if speed is not None:
            self.speed = speed
        self.target = target
        self.update(now)

    @property
    def moving(self) -> bool:
        return self.pulse != self.target


class ServoEmulator(PtyService):
    """The controller's behaviour: `feed(request bytes) -> reply bytes`, positions by its clock.

    `fault` makes it misbehave on purpose: "silent" answers nothing, "garbage" answers nonsense.
    `history()` gives the latest targets it was sent, `(clock time, channel, pulse us)`, as the
    host commanded them (for Firmata the value written, before the Servo library clamps it).
    """

    def __init__(
        self, protocol: str, clock: Callable[[], float] = time.monotonic, fault: str | None = None
    ) -> None:
        super().__init__()
        if protocol not in PROTOCOLS:
            raise ServantError(
                f"servo protocol {protocol!r} is unknown; use one of {', '.join(PROTOCOLS)}"
            )
        if fault not in FAULTS:
            raise ValueError(f"fault must be one of {FAULTS}")
        self.protocol = protocol
        self.clock = clock
        self.fault = fault
        self.channels: dict[int, Channel] = {}
        self.errors = 0  # Maestro error bits, cleared when read
        self.pin_modes: dict[int, int] = {}
        self.pin_states: dict[int, int] = {}
        self.servo_ranges: dict[int, tuple[int, int]] = {}
        self._history: deque[tuple[float, int, float]] = deque(maxlen=HISTORY)
        self._pending = b""
        self._lock = threading.Lock()
        self.port: str | None = None

    # -- behaviour ------------------------------------------------------------------------

    def channel(self, number: int) -> Channel:
        return self.channels.setdefault(number, Channel())

    def pulse(self, number: int) -> float | None:
        """The pulse width (us) the channel sends now, by the emulator's clock."""
        with self._lock:
            channel = self.channel(number)
            channel.update(self.clock())
            return channel.pulse

    def history(self) -> list[tuple[float, int, float]]:
        """The targets received, oldest first (the latest `HISTORY`)."""
        with self._lock:
            return list(self._history)

    def feed(self, data: bytes) -> bytes:
        """Take bytes from the host; return what the controller answers."""
        with self._lock:
            self._pending += data
            reply = {"maestro": self._maestro, "ssc32": self._ssc32, "firmata": self._firmata}[
                self.protocol
            ]()
        if self.fault == "silent":
            return b""
        if self.fault == "garbage" and reply:
            return GARBAGE
        return reply

    def _maestro(self) -> bytes:
        sizes = {
            maestro.SET_TARGET: 3,
            maestro.SET_SPEED: 3,
            maestro.SET_ACCELERATION: 3,
            maestro.GET_POSITION: 1,
            maestro.GET_ERRORS: 0,
        }
        reply = b""
        buf = self._pending
        while buf:
            command = buf[0]
            if command not in sizes:
                self.errors |= 1 << 4  # serial protocol error, as the Maestro reports it
                buf = buf[1:]
                continue
            size = sizes[command]
            data = buf[1 : 1 + size]
            interrupted = next((i for i, b in enumerate(data) if b >= 0x80), None)
            if interrupted is not None:  # a new command cut this one short: the Maestro drops it
                self.errors |= 1 << 4
                buf = buf[1 + interrupted :]
                continue
            if len(data) < size:
                break
            buf = buf[1 + size :]
            now = self.clock()
            if command == maestro.GET_ERRORS:
                reply += maestro.encode_word(self.errors)
                self.errors = 0
                continue
            channel = self.channel(data[0])
            value = data[1] | data[2] << 7 if size == 3 else 0
            if command == maestro.SET_TARGET:
                if value:
                    self._history.append((now, data[0], value / 4))
                channel.aim(value / 4 if value else None, now)
            elif command == maestro.SET_SPEED:
                channel.aim(channel.target, now, speed=value * 25.0)
            elif command == maestro.GET_POSITION:
                channel.update(now)
                reply += maestro.encode_word(round((channel.pulse or 0) * 4))
            # Set Acceleration is accepted and ignored: the emulator ramps at constant speed.
        self._pending = buf
        return reply

    _SSC32_TOKEN = re.compile(r"\s*(VER|QP|Q|#|P|S|T)\s*(\d*)")

    def _ssc32(self) -> bytes:
        reply = b""
        while (end := self._pending.find(b"\r")) >= 0:
            line, self._pending = self._pending[:end], self._pending[end + 1 :]
            reply += self._ssc32_line(line.decode("ascii", "replace").upper())
        return reply

    def _ssc32_line(self, line: str) -> bytes:
        group: dict[int, dict[str, int]] = {}
        reply = b""
        time_ms = 0
        current: int | None = None
        pos = 0
        while pos < len(line.rstrip()):
            match = self._SSC32_TOKEN.match(line, pos)
            if match is None:
                return b""  # the SSC-32 ignores a command it cannot parse
            pos = match.end()
            word, number = match.group(1), int(match.group(2) or 0)
            if word == "VER":
                reply += SSC32_VERSION + b"\r"
            elif word == "QP":
                channel = self.channel(number)
                channel.update(self.clock())
                reply += bytes((ssc32.encode_pulse_byte(channel.pulse or 0),))
            elif word == "Q":
                moving = any(c.moving for c in self._updated_channels())
                reply += b"+" if moving else b"."
            elif word == "#":
                current = number
                group.setdefault(number, {})
            elif word == "T":
                time_ms = number
            elif current is not None:
                group[current][word] = number
        self._ssc32_group_move(group, time_ms)
        return reply

    def _updated_channels(self) -> list[Channel]:
        now = self.clock()
        for channel in self.channels.values():
            channel.update(now)
        return list(self.channels.values())

    def _ssc32_group_move(self, group: dict[int, dict[str, int]], time_ms: int) -> None:
        """Channels of one command start and end together: the slowest one sets the duration."""
        now = self.clock()
        moves = {n: spec for n, spec in group.items() if "P" in spec}
        duration = time_ms / 1000
        for number, spec in moves.items():
            channel = self.channel(number)
            channel.update(now)
            if channel.pulse is not None and spec.get("S"):
                duration = max(duration, abs(spec["P"] - channel.pulse) / spec["S"])
        for number, spec in moves.items():
            channel = self.channel(number)
            self._history.append((now, number, float(spec["P"])))
            distance = abs(spec["P"] - channel.pulse) if channel.pulse is not None else 0.0
            speed = distance / duration if duration > 0 else 0.0
            channel.aim(float(spec["P"]), now, speed=speed)

    def _firmata(self) -> bytes:
        reply = b""
        buf = self._pending
        while buf:
            command = buf[0]
            if command == firmata.START_SYSEX:
                end = buf.find(bytes((firmata.END_SYSEX,)))
                if end < 0:
                    break
                reply += self._firmata_sysex(buf[1:end])
                buf = buf[end + 1 :]
            elif command == firmata.REPORT_VERSION:
                reply += bytes((firmata.REPORT_VERSION, *FIRMATA_VERSION))
                buf = buf[1:]
            elif command == firmata.SET_PIN_MODE or command & 0xF0 == firmata.ANALOG_MESSAGE:
                if len(buf) < 3:
                    break
                if command == firmata.SET_PIN_MODE:
                    self._firmata_pin_mode(buf[1], buf[2])
                else:
                    self._firmata_write(command & 0x0F, firmata.from_seven_bit(buf[1:3]))
                buf = buf[3:]
            else:
                buf = buf[1:]  # StandardFirmata skips what it does not understand
        self._pending = buf
        return reply

    def _firmata_pin_mode(self, pin: int, mode: int) -> None:
        self.pin_modes[pin] = mode
        if mode == firmata.PIN_MODE_SERVO:
            self.servo_ranges.setdefault(pin, FIRMATA_DEFAULT_PULSES)

    def _firmata_sysex(self, body: bytes) -> bytes:
        if not body:
            return b""
        kind, data = body[0], body[1:]
        if kind == firmata.SERVO_CONFIG and len(data) >= 5:
            pin = data[0]
            self.servo_ranges[pin] = (
                firmata.from_seven_bit(data[1:3]),
                firmata.from_seven_bit(data[3:5]),
            )
            self.pin_modes[pin] = firmata.PIN_MODE_SERVO
        elif kind == firmata.EXTENDED_ANALOG and len(data) >= 2:
            self._firmata_write(data[0], firmata.from_seven_bit(data[1:]))
        elif kind == firmata.PIN_STATE_QUERY and data:
            pin = data[0]
            return firmata.pin_state_response(
                pin, self.pin_modes.get(pin, 0), self.pin_states.get(pin, 0)
            )
        return b""

    def _firmata_write(self, pin: int, value: int) -> None:
        if self.pin_modes.get(pin) != firmata.PIN_MODE_SERVO:
            return
        self._history.append((self.clock(), pin, float(value)))
        low, high = self.servo_ranges[pin]
        # The Servo library: below 544 the value is an angle; pulses are clamped to the range.
        pulse = low + (high - low) * min(value, 180) / 180 if value < 544 else value
        self.pin_states[pin] = value
        self.channel(pin).aim(float(min(max(pulse, low), high)), self.clock())

    # -- the pty --------------------------------------------------------------------------

    def start(self, link: str | Path | None = None) -> str:
        """Serve on a new pty; return the port to open (`link`, a symlink to it, if given)."""
        self._pty = PtyPort(link)
        self.port = self._pty.device
        self._stop.clear()
        self._thread = threading.Thread(
            target=self._serve, name=f"servo-emulator-{self.protocol}", daemon=True
        )
        self._thread.start()
        return self._pty.port

    def _serve(self) -> None:
        assert self._pty is not None
        master = self._pty.master
        while not self._stop.is_set():
            ready, _, _ = select.select([master], [], [], 0.05)
            if not ready:
                continue
            try:
                data = os.read(master, 4096)
            except OSError:
                return
            reply = self.feed(data)
            if reply:
                try:
                    os.write(master, reply)
                except OSError:
                    return

    @property
    def serving(self) -> bool:
        """Whether its pty is open: False once stopped (unplugged)."""
        return self._pty is not None


def start_emulator(
    protocol: str,
    *,
    link: str | Path | None = None,
    clock: Callable[[], float] = time.monotonic,
    fault: str | None = None,
) -> tuple[ServoEmulator, str]:
    """An emulator serving on a pty, and the port name to open; call `emulator.stop()` when done."""
    emulator = ServoEmulator(protocol, clock=clock, fault=fault)
    return emulator, emulator.start(link)
