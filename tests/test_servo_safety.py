"""Property: whatever poses arrive, at whatever times, no command leaves the joints' limits or
outruns their speed. The bytes are decoded by the emulator's own parser, independently of the
encoders that produced them."""

from __future__ import annotations

import math
from dataclasses import replace

from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from servant_core.errors import ServantError
from servant_core.servo.base import pulse_speed
from servant_core.servo.calibration import pulse_to_angle
from servant_core.servo.emulator import ServoEmulator
from servant_core.servo.link import MAX_STEP_S, ManualClock, ServoLink
from servant_core.settings import Joint, default_joints

JOINTS = default_joints()
NAMES = [j.name for j in JOINTS] + ["wrist"]
# Rounding to the protocol's unit (0.25 us, 1 us) may overshoot by half a unit.
TOLERANCE_US = 0.5

angles = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-400, max_value=400),
)
poses = st.dictionaries(st.sampled_from(NAMES), angles, max_size=4)
events = st.lists(
    st.tuples(
        st.floats(min_value=0, max_value=5),
        poses,
        st.booleans(),
        st.integers(min_value=0, max_value=5),
    ),
    max_size=12,
)


def commanded_pulses(emulator: ServoEmulator) -> dict[int, float]:
    if emulator.protocol == "firmata":  # the raw value written, before the Servo library's clamp
        return {pin: float(value) for pin, value in emulator.pin_states.items()}
    return {n: c.target for n, c in emulator.channels.items() if c.target is not None}


@settings(max_examples=150, deadline=None)
@given(protocol=st.sampled_from(["maestro", "ssc32", "firmata"]), events=events)
def test_no_command_leaves_the_limits_or_outruns_the_speed(protocol, events):
    clock = ManualClock()
    decoder = ServoEmulator(protocol, clock=clock)
    sent: list[tuple[float, dict[int, float]]] = []

    def on_bytes(data: bytes) -> None:
        decoder.feed(data)
        sent.append((clock(), commanded_pulses(decoder)))

    link = ServoLink.open(
        None, protocol, JOINTS, dry_run=True, clock=clock, sleep=clock.sleep, on_bytes=on_bytes
    )
    link.arm()
    for pause, pose, wait, steps in events:
        clock.sleep(pause)
        try:
            link.move_to(pose, wait=wait)
        except ServantError:
            pass  # refused (unknown joint, not a number): safe; the checks below still run
        for _ in range(steps):
            clock.sleep(0.03)
            link.step()

    by_channel = {j.channel: j for j in JOINTS}
    previous: dict[int, tuple[float, float]] = {}
    for t, pulses in sent:
        for channel, pulse in pulses.items():
            joint = by_channel[channel]
            assert math.isfinite(pulse)
            assert joint.min_pulse_us - TOLERANCE_US <= pulse <= joint.max_pulse_us + TOLERANCE_US
            if channel in previous:
                t0, p0 = previous[channel]
                allowed = pulse_speed(joint) * min(t - t0, MAX_STEP_S)
                assert abs(pulse - p0) <= allowed + 2 * TOLERANCE_US + 1e-9
            previous[channel] = (t, pulse)


finite = st.floats(min_value=-1e308, max_value=1e308, allow_nan=False)


@st.composite
def loadable_joints(draw):
    """Joint settings of any magnitude, kept only where the settings would load them."""
    angle = st.one_of(st.floats(-400, 400), st.floats(-400, 400), st.floats(-400, 400), finite)
    low, high = sorted([draw(angle), draw(angle)])
    pulses = sorted(draw(st.floats(380, 2620)) for _ in range(2))
    speed = draw(st.one_of(st.floats(0.5, 500), st.floats(0.5, 500), finite))
    joint = Joint("shoulder", 3, low, high, *pulses, speed, 0.0)
    home = low + draw(st.floats(0, 1)) * (high - low)
    joint = replace(joint, home_angle=min(max(home, low), high) if math.isfinite(home) else low)
    assume(not joint.problems())
    return joint


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(
    joint=loadable_joints(),
    reported_us=st.floats(400, 2600),
    target=st.one_of(finite, st.floats(-400, 400)),
)
def test_every_move_ends_in_a_time_bounded_by_the_joints_speed(joint, reported_us, target):
    """Issue 41 item 1: a finite but absurd max_angle (1e308) made `servo move` run for ever.
    Whatever settings load and whatever pulse the controller reports, a move ends within twice
    the time the joint's whole range takes at its speed, plus a second, inside its limits."""
    clock = ManualClock()
    link = ServoLink.open(None, "maestro", [joint], dry_run=True, clock=clock, sleep=clock.sleep)
    link.arm()
    link.commanded["shoulder"] = pulse_to_angle(joint, reported_us)  # what a controller said
    start = clock()
    link.move_to({"shoulder": target})
    bound = 2 * (joint.max_angle - joint.min_angle) / joint.max_speed_deg_s + 1.0
    assert clock() - start <= bound + 0.05
    assert link.at_goal
    assert joint.min_angle <= link.commanded["shoulder"] <= joint.max_angle


def test_a_joint_range_beyond_a_servos_is_refused_in_one_line():
    """The settings of issue 41 item 1 (max_angle 1e308) and a calibration a hair wide no
    longer load."""
    base = default_joints()[0]
    for joint in (replace(base, max_angle=1e308), replace(base, max_pulse_us=1000.001)):
        (line,) = joint.problems()
        assert "\n" not in line and joint.name in line
