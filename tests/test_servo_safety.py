"""Property: whatever poses arrive, at whatever times, no command leaves the joints' limits or
outruns their speed. The bytes are decoded by the emulator's own parser, independently of the
encoders that produced them."""

from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st

from servant_core.errors import ServantError
from servant_core.servo.base import pulse_speed
from servant_core.servo.emulator import ServoEmulator
from servant_core.servo.link import MAX_STEP_S, ManualClock, ServoLink
from servant_core.settings import default_joints

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
