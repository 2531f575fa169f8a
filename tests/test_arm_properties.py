"""Property (issue 13): whatever stream of commands arrives, and wherever the controller is
unplugged, the arm never leaves its limits, never outruns its speed, never moves unless armed,
and is disarmed after any fault of the link.

Random streams of arm / disarm / move / step / read / wait / unplug (the emulator's pty closed,
also in the middle of a move) / plug back in, driven by hypothesis through a real `ServoLink`
on the project's emulator on a pty. What the controller was sent is what the emulator parsed
(`ServoEmulator.history`), decoded independently of the link's encoders.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from servant_core.errors import ServantError
from servant_core.servo.base import pulse_speed
from servant_core.servo.emulator import ServoEmulator, start_emulator
from servant_core.servo.link import MAX_STEP_S, ManualClock, ServoLink
from servant_core.settings import default_joints

JOINTS = default_joints()
BY_CHANNEL = {j.channel: j for j in JOINTS}
NAMES = [j.name for j in JOINTS]
TOLERANCE_US = 0.5  # rounding to the protocol's unit (0.25 us, 1 us)
REFUSALS = ("not armed", "no joint named", "is not an angle")  # refused before any I/O

angles = st.one_of(
    st.floats(min_value=-400, max_value=400),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e300]),
)
poses = st.dictionaries(st.sampled_from([*NAMES, "wrist"]), angles, min_size=1, max_size=4)
pauses = st.floats(min_value=0, max_value=3)


class ArmStreams(RuleBasedStateMachine):
    """One arm on one emulated controller; each rule is one thing a user, the engine or the
    cable can do. The invariant looks at what reached the controller since the last rule."""

    def __init__(self) -> None:
        super().__init__()
        self.emulators: list[ServoEmulator] = []
        self.link: ServoLink | None = None
        self.folder = tempfile.TemporaryDirectory(prefix="servant-arm-")

    @initialize(protocol=st.sampled_from(["maestro", "ssc32", "firmata"]))
    def connect(self, protocol: str) -> None:
        self.clock = ManualClock()
        self.protocol = protocol
        self.port = str(Path(self.folder.name) / "servo")  # a stable name, as udev gives
        self.plugged: ServoEmulator | None = None
        self.plug()
        self.link = ServoLink.open(
            self.port,
            protocol,
            JOINTS,
            timeout=5.0,  # a slow machine must not look like a silent controller
            clock=self.clock,
            sleep=self.clock.sleep,
            reconnect_every=0.0,
        )
        self.started = self.clock()
        self.armed_before = False
        self.arming = False
        self.seen = 0
        self.reference: dict[int, float] = {}

    def plug(self) -> None:
        emulator, _ = start_emulator(self.protocol, link=self.port, clock=self.clock)
        self.emulators.append(emulator)
        self.plugged = emulator
        self.seen = 0
        self.reference = {}  # a controller just plugged in sends no pulse yet

    def teardown(self) -> None:
        if self.link is not None:
            self.link.close()
        for emulator in self.emulators:
            emulator.stop()
        self.folder.cleanup()

    # -- what may happen --------------------------------------------------------------------

    def attempt(self, action) -> None:
        """Run `action`; a refusal is fine, any other error must have disarmed the link."""
        assert self.link is not None
        try:
            action()
        except ServantError as error:
            if not any(refusal in str(error) for refusal in REFUSALS):
                assert not self.link.armed, f"armed after a link fault: {error}"

    @rule()
    def arm(self) -> None:
        assert self.link is not None
        self.arming = True
        self.attempt(self.link.arm)
        if self.link.armed:  # where the controller said each joint is: moves start from there
            self.check()
            self.reference = {j.channel: self.plugged_pulse(j.channel) for j in JOINTS}

    @rule()
    def disarm(self) -> None:
        assert self.link is not None
        self.link.disarm()

    @rule(pose=poses, wait=st.booleans())
    def move(self, pose: dict[str, float], wait: bool) -> None:
        assert self.link is not None
        link = self.link
        self.attempt(lambda: link.move_to(pose, wait=wait))

    @precondition(lambda self: self.plugged is not None)
    @rule(pose=poses, sleeps=st.integers(min_value=0, max_value=20))
    def unplug_mid_move(self, pose: dict[str, float], sleeps: int) -> None:
        assert self.link is not None
        link, plugged, count = self.link, self.plugged, [0]
        assert plugged is not None

        def sleep(seconds: float) -> None:
            self.clock.sleep(seconds)
            count[0] += 1
            if count[0] == sleeps:
                self.check()
                plugged.stop()

        link.sleep = sleep
        try:
            self.attempt(lambda: link.move_to(pose, wait=True))
        finally:
            link.sleep = self.clock.sleep
        if not plugged.serving:  # unplugged during the move
            self.plugged = None

    @rule(pause=pauses)
    def step(self, pause: float) -> None:
        assert self.link is not None
        self.clock.sleep(pause)
        self.attempt(self.link.step)

    @rule()
    def read(self) -> None:
        assert self.link is not None
        self.attempt(self.link.read_positions)

    @rule(pause=pauses)
    def wait(self, pause: float) -> None:
        self.clock.sleep(pause)

    @precondition(lambda self: self.plugged is not None)
    @rule()
    def unplug(self) -> None:
        assert self.plugged is not None
        self.check()
        self.plugged.stop()
        self.plugged = None

    @precondition(lambda self: self.plugged is None)
    @rule()
    def plug_back_in(self) -> None:
        assert self.link is not None
        noticed = not self.link.connected  # else its next I/O on the old port fails and disarms
        self.plug()
        self.attempt(self.link.reconnect)
        if noticed:
            assert not self.link.armed  # back, but only the user arms it

    # -- what must hold ---------------------------------------------------------------------

    def plugged_pulse(self, channel: int) -> float:
        assert self.plugged is not None
        pulse = self.plugged.pulse(channel)
        assert pulse is not None
        return pulse

    def sync(self) -> None:
        """Wait until the controller has parsed every byte sent so far: its answer to a query
        comes after them on the line. A link that cannot ask is not connected or just failed."""
        assert self.link is not None
        if self.plugged is not None and self.link.connected:
            armed = self.link.armed
            try:
                self.link.read_positions()
            except ServantError:
                assert not self.link.armed
                return
            assert self.link.armed == armed

    @invariant()
    def the_controller_was_only_sent_safe_targets(self) -> None:
        if self.link is not None:
            self.check()

    def check(self) -> None:
        """What the controller received since the last check: within the limits, no faster than
        the joints' speeds over the time that passed, and nothing unless armed (or arming)."""
        assert self.link is not None
        self.sync()
        now = self.clock()
        elapsed = now - self.started
        new = self.plugged.history()[self.seen :] if self.plugged is not None else []
        if new:
            assert self.armed_before or self.arming, f"moved while disarmed: {new}"
        travelled: dict[int, float] = {}
        for _, channel, pulse in new:
            joint = BY_CHANNEL[channel]
            assert joint.min_pulse_us - TOLERANCE_US <= pulse <= joint.max_pulse_us + TOLERANCE_US
            if channel in self.reference:
                travelled[channel] = travelled.get(channel, 0.0) + abs(
                    pulse - self.reference[channel]
                )
            self.reference[channel] = pulse
        for channel, distance in travelled.items():
            # Each step may use at most MAX_STEP_S of time before this rule began.
            allowed = pulse_speed(BY_CHANNEL[channel]) * (elapsed + MAX_STEP_S)
            assert distance <= allowed + 2 * TOLERANCE_US * len(new) + 1e-6, (channel, distance)
        if self.plugged is not None:
            self.seen += len(new)
        self.started = now
        self.armed_before = self.link.armed
        self.arming = False


ArmStreams.TestCase.settings = settings(
    max_examples=100,
    stateful_step_count=20,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
TestRandomCommandStreamsWithUnplugging = ArmStreams.TestCase
