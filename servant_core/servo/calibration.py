"""Angles to pulse widths and back, per joint; the clamping and rate limiting every command obeys.

All pure functions: the link applies them to every pose before any byte is encoded.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from servant_core.errors import ServantError
from servant_core.settings import Joint


def angle_to_pulse(joint: Joint, angle: float) -> float:
    """The pulse width (us) for `angle`, clamped to the joint's limits first."""
    angle = min(max(angle, joint.min_angle), joint.max_angle)
    fraction = (angle - joint.min_angle) / (joint.max_angle - joint.min_angle)
    return joint.min_pulse_us + fraction * (joint.max_pulse_us - joint.min_pulse_us)


def pulse_to_angle(joint: Joint, pulse_us: float) -> float:
    """The angle a pulse width stands for (not clamped: a controller may report anything)."""
    fraction = (pulse_us - joint.min_pulse_us) / (joint.max_pulse_us - joint.min_pulse_us)
    return joint.min_angle + fraction * (joint.max_angle - joint.min_angle)


def clamp_pose(
    joints: Mapping[str, Joint], pose: Mapping[str, float]
) -> tuple[dict[str, float], list[str]]:
    """`pose` within the joints' limits, and one note per angle that had to be clamped.

    A joint that does not exist, or an angle that is not a finite number, is refused outright:
    guessing what the user meant is not safe for an arm.
    """
    clamped: dict[str, float] = {}
    notes: list[str] = []
    for name, angle in pose.items():
        if name not in joints:
            raise ServantError(
                f"no joint named {name!r}; the arm's joints are: {', '.join(joints)}"
            )
        try:
            value = float(angle)
        except (TypeError, ValueError, OverflowError):  # OverflowError: an int beyond floats
            value = math.nan
        if not math.isfinite(value):
            raise ServantError(f"{name}: {angle!r} is not an angle in degrees")
        joint = joints[name]
        limited = min(max(value, joint.min_angle), joint.max_angle)
        if limited != value:
            notes.append(
                f"{name}: {value:g} is beyond {joint.min_angle:g}..{joint.max_angle:g} degrees, "
                f"clamped to {limited:g}"
            )
        clamped[name] = limited
    return clamped, notes


def rate_limit(
    joints: Mapping[str, Joint],
    current: Mapping[str, float],
    goal: Mapping[str, float],
    dt: float,
) -> dict[str, float]:
    """How far towards `goal` each joint may go from `current` in `dt` seconds at its max speed."""
    step: dict[str, float] = {}
    for name, target in goal.items():
        reach = joints[name].max_speed_deg_s * max(dt, 0.0)
        here = current[name]
        step[name] = min(max(target, here - reach), here + reach)
    return step
