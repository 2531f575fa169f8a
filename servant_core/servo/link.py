"""The serial link to the arm's servo controller (pyserial), and the safety rules it enforces.

Every angle is clamped to its joint's limits before encoding; an unknown joint or a non-number is
refused. Each `step` moves a joint at most `max_speed_deg_s` times the time since the last (at most
`MAX_STEP_S`); controllers with a speed limit (Maestro, SSC-32) get it too. Nothing moves unless
armed; any fault disarms, and `reconnect` (also tried by `arm`, `read_positions`) reopens a lost
port still disarmed. A dry run opens no port and hands every command's bytes to `on_bytes`.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from typing import TypeVar

import serial

from servant_core.errors import ServantError
from servant_core.events import ArmState
from servant_core.serial_port import PORT_ERRORS, open_serial
from servant_core.servo import ProtocolError, ServoProtocol, protocol_for
from servant_core.servo.base import Move, pulse_speed
from servant_core.servo.calibration import angle_to_pulse, clamp_pose, pulse_to_angle, rate_limit
from servant_core.settings import Joint

MAX_STEP_S = 0.1
RECONNECT_EVERY_S = 1.0
MAX_TIMEOUT_S = 60.0  # longer than any controller needs to answer; more looks like a hang
MAX_RECORD_S = 600.0  # a recording is the user guiding the arm: minutes at most
MAX_REPLY_BYTES = 4096  # far more than any reply this link asks for: the rest is line noise
DRY_RUN_PORT = "dry-run"
T = TypeVar("T")


def seconds(value: object, what: str, most: float, *, zero: bool = False) -> float:
    """`value` as a number of seconds up to `most` (above 0 unless `zero`), or a one-line error.

    NaN and infinity are refused: a deadline that never comes is a hang.
    """
    number = value if isinstance(value, int | float) and not isinstance(value, bool) else math.nan
    if not ((0 <= number) if zero else (0 < number)) or not number <= most:
        lowest = "0" if zero else "above 0"
        raise ServantError(f"{what} must be {lowest} to {most:g} seconds, not {value!r}")
    return float(number)


def _reason(exc: BaseException) -> str:
    """The words of a port error: termios.error carries `(errno, text)`, shown as a tuple."""
    if len(exc.args) == 2 and isinstance(exc.args[1], str):
        return exc.args[1]
    return str(exc)


class ManualClock:
    """A clock that only moves when slept on: dry runs finish at once, tests step time exactly."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += max(0.0, seconds)


class ServoLink:
    """An arm on a servo controller. Build it with `ServoLink.open(...)`.

    `clock` and `sleep` drive the rate limiting, so tests can step time; waits for the
    controller's answers use the real clock.
    """

    def __init__(
        self,
        protocol: ServoProtocol,
        joints: Sequence[Joint],
        port: str | None,
        *,
        dry_run: bool = False,
        baudrate: int | None = None,
        timeout: float = 0.5,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        on_bytes: Callable[[bytes], None] | None = None,
        reconnect_every: float = RECONNECT_EVERY_S,
    ) -> None:
        self.protocol = protocol
        self.joints = {j.name: j for j in joints}
        self.port = DRY_RUN_PORT if dry_run else port
        self.dry_run = dry_run
        self.baudrate = baudrate or protocol.baudrate
        self.timeout = seconds(timeout, "the timeout", MAX_TIMEOUT_S)
        self.clock = clock
        self.sleep = sleep
        self.sent: deque[bytes] = deque(maxlen=1000)
        self.on_bytes = on_bytes or self.sent.append
        self.controller: str | None = None  # what the controller said it is
        self.armed = False
        self.commanded: dict[str, float] = {}  # the angles last sent (or read when arming)
        self.goal: dict[str, float] = {}
        self.notes: list[str] = []  # what the last `move_to` had to clamp
        self._commanded_at = 0.0
        self._last_move: bytes | None = None  # the last move command sent since arming
        self._serial: serial.SerialBase | None = None
        self.reconnect_every = reconnect_every
        self._last_attempt = -math.inf
        self._lock = threading.RLock()

    @classmethod
    def open(
        cls,
        port: str | None,
        protocol: str,
        joints: Sequence[Joint],
        **options,
    ) -> ServoLink:
        """Connect to the controller on `port`, check it answers; `dry_run=True` needs no port."""
        proto = protocol_for(protocol)
        problems = [line for j in joints for line in j.problems()] + proto.check_joints(joints)
        if not joints:
            problems.append("the arm has no joints")
        if problems:
            raise ServantError(f"settings: {problems[0]}; fix the joints in the settings file")
        if not options.get("dry_run") and not port:
            raise ServantError(
                "no serial port given; pass --port (see `servant servo list-ports`) or --dry-run"
            )
        link = cls(proto, joints, port, **options)
        if not link.dry_run:
            link._connect()
        else:
            link._send(proto.setup(joints))
        return link

    # -- connection -------------------------------------------------------------------------

    @property
    def connected(self) -> bool:
        return self.dry_run or self._serial is not None

    def _connect(self) -> None:
        assert self.port is not None
        handle = open_serial(self.port, self.baudrate)
        self._serial = handle
        try:
            self.controller = self._exchange(self.protocol.probe(), self.protocol.parse_probe)
            self._send(self.protocol.setup(list(self.joints.values())))
        except ServantError:
            self._drop()
            raise

    def reconnect(self) -> bool:
        """Reopen a lost port if it is back (tried at most every `reconnect_every` s), disarmed."""
        with self._lock:
            if self.connected:
                return True
            now = time.monotonic()
            if now - self._last_attempt < self.reconnect_every:
                return False
            self._last_attempt = now
            try:
                self._connect()
            except ServantError:
                return False
            return True

    def _drop(self) -> None:
        self.armed = False
        if self._serial is not None:
            try:
                self._serial.close()
            except PORT_ERRORS:
                pass  # the port is gone already; closing is only tidying up
        self._serial = None

    def _io(self, action: Callable[[], T]) -> T:
        """Run serial I/O; a lost port disarms the link and is said in one line."""
        try:
            return action()
        except PORT_ERRORS as exc:
            self._drop()
            raise ServantError(
                f"{self.port}: the link to the {self.protocol.title} was lost ({_reason(exc)}); "
                "the arm is disarmed; reconnect the controller, then arm again"
            ) from exc

    def _send(self, data: bytes) -> None:
        if not data:
            return
        if self.dry_run:
            self.on_bytes(data)
            return
        handle = self._require_serial()
        self._io(lambda: (handle.write(data), handle.flush()))

    def _require_serial(self) -> serial.SerialBase:
        if self._serial is None and not self.reconnect():
            raise ServantError(
                f"{self.port}: the {self.protocol.title} is not connected; "
                "plug it in (Servant reconnects by itself)"
            )
        assert self._serial is not None
        return self._serial

    def _exchange(self, request: bytes, parse: Callable[[bytes], tuple[T, int] | None]) -> T:
        """Send `request` and read until `parse` accepts the reply, within `timeout` seconds.

        A controller that does not answer, or answers nonsense, disarms the link: what it does
        with the next command is anyone's guess. The port stays open, to arm again.
        """
        handle = self._require_serial()
        self._io(handle.reset_input_buffer)
        self._send(request)
        deadline = time.monotonic() + self.timeout
        buffer = b""
        while True:
            try:
                if len(buffer) > MAX_REPLY_BYTES:
                    raise ProtocolError(f"{len(buffer)} bytes and still no complete reply")
                parsed = parse(buffer)
            except ProtocolError as exc:
                self.disarm()
                self._io(handle.reset_input_buffer)
                raise ServantError(
                    f"{self.port}: the controller sent bytes that are not a "
                    f"{self.protocol.title} reply "
                    f"({exc}); check the protocol and the baud rate ({self.baudrate})"
                ) from exc
            if parsed is not None:
                return parsed[0]
            if time.monotonic() > deadline:
                self.disarm()
                raise ServantError(
                    f"{self.port}: no answer from a {self.protocol.title} "
                    f"within {self.timeout:g} s; "
                    "check it is powered and that the protocol and baud rate are right"
                )
            buffer += self._io(lambda: handle.read(max(1, min(handle.in_waiting, 1024))))

    # -- arming and moving ------------------------------------------------------------------

    def arm(self) -> dict[str, float]:
        """Allow motion. Joints whose controller sends no pulse yet are put at their home angle."""
        with self._lock:
            known = self.read_positions()
            home = {n: j.home_angle for n, j in self.joints.items() if n not in known}
            self.commanded = {**known, **home}
            self.goal = {}
            self._commanded_at = self.clock()
            self._last_move = None
            self._send_pose(home)
            self.armed = True
            return dict(self.commanded)

    def disarm(self) -> None:
        """Stop sending commands; the controller holds the last pose (the arm does not drop)."""
        with self._lock:
            self.armed = False
            self.goal = {}

    def move_to(self, pose: Mapping[str, float], wait: bool = True) -> dict[str, float]:
        """Aim at `pose` (clamped to the limits, see `notes`) and move there at the joints' speeds.

        With `wait` (the default) it blocks, stepping, until the arm is there or is disarmed (from
        any thread); without, it takes the first step only and `step` (or `settle`) goes on.
        Returns the angles commanded when it returns, for the joints of `pose`.
        """
        with self._lock:
            if not self.armed:
                raise ServantError("the arm is not armed; arm it before moving it")
            clamped, self.notes = clamp_pose(self.joints, pose)
            self.goal.update(clamped)
            commanded = self.step()
        if not wait:
            return commanded
        self.settle()
        return {n: self.commanded[n] for n in clamped}

    def step(self) -> dict[str, float]:
        """Move on towards the goal as far as the speed limits allow since the last step."""
        with self._lock:
            if not self.armed or not self.goal:
                return {}
            now = self.clock()
            dt = min(now - self._commanded_at, MAX_STEP_S)
            limited = rate_limit(self.joints, self.commanded, self.goal, dt)
            # Limits beat speed: a joint found outside its limits is brought back at once.
            pose, _ = clamp_pose(self.joints, limited)
            # A step shorter than the controller's pulse resolution says nothing new: not sent.
            self._send_pose(pose, again=False)
            self.commanded.update(pose)
            self._commanded_at = now
            return pose

    @property
    def at_goal(self) -> bool:
        return all(self.commanded.get(n) == a for n, a in self.goal.items())

    def settle(self, interval: float = 0.02) -> dict[str, float]:
        """Step until the goal is reached, the link is disarmed, or twice the time the move needs
        at full speed has passed by the link's clock (a step can only be late, never too long).
        A move never needs longer than crossing a joint's whole range: the first step brings a
        joint found outside it back within, whatever the controller reported."""
        with self._lock:
            needed = max(
                (
                    min(abs(a - self.commanded[n]), j.max_angle - j.min_angle) / j.max_speed_deg_s
                    for n, a in self.goal.items()
                    for j in (self.joints[n],)
                ),
                default=0.0,
            )
        end = self.clock() + 2 * needed + 1.0
        while self.armed and not self.at_goal and self.clock() < end:
            self.sleep(interval)
            self.step()
        return {n: self.commanded[n] for n in self.goal}

    def _send_pose(self, pose: Mapping[str, float], *, again: bool = True) -> None:
        """Send `pose`; with `again` False, not when its command is the last one sent."""
        moves = [
            Move(
                self.joints[n].channel,
                angle_to_pulse(self.joints[n], a),
                pulse_speed(self.joints[n]),
            )
            for n, a in pose.items()
        ]
        if not moves:
            return
        command = self.protocol.move(moves)
        if again or command != self._last_move:
            self._send(command)
            self._last_move = command

    # -- reading ----------------------------------------------------------------------------

    def read_positions(self) -> dict[str, float]:
        """The angle each joint's pulse stands for now, as the controller reports it.

        Joints whose channel sends no pulse yet are left out. A dry run reports what it commanded.
        """
        with self._lock:
            if self.dry_run:
                return dict(self.commanded)
            names = list(self.joints)
            channels = [self.joints[n].channel for n in names]
            pulses = self._exchange(
                self.protocol.query(channels),
                lambda buffer: self.protocol.parse_positions(buffer, channels),
            )
            return {
                n: pulse_to_angle(self.joints[n], p)
                for n, p in zip(names, pulses, strict=True)
                if p is not None
            }

    def record(self, duration: float, interval: float = 0.1) -> list[dict[str, float]]:
        """The paper's recording mode: the positions read every `interval` s for `duration` s.

        The user guides the arm meanwhile; the last sample is the pose to teach. Hobby servos
        report only what they are sent, so guiding by hand needs servos with position feedback;
        with others the user moves the arm through the controller and records where it ended.
        """
        duration = seconds(duration, "a recording", MAX_RECORD_S, zero=True)
        interval = seconds(interval, "the sampling interval", MAX_RECORD_S)
        samples = []
        end = self.clock() + duration
        while True:
            samples.append(self.read_positions())
            if self.clock() >= end:
                return samples
            self.sleep(interval)

    def status(self) -> ArmState:
        with self._lock:
            return ArmState(
                t=self.clock(),
                connected=self.connected,
                armed=self.armed,
                protocol=self.protocol.name,
                port=self.port,
                angles=dict(self.commanded),
                target=dict(self.goal) or None,
            )

    def close(self) -> None:
        with self._lock:
            self.disarm()
            self._drop()

    def __enter__(self) -> ServoLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
