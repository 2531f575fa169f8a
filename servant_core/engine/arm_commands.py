"""The arm as the engine offers it to front ends: each command is `ArmControl`'s (see `arm`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from servant_core.engine.arm import ArmControl, PoseFor


class ArmCommands:
    """The engine's arm commands (`Engine` is one), over the `ArmControl` it keeps in `_arm`."""

    _arm: ArmControl

    @property
    def link(self) -> Any:
        """The attached servo link, or None."""
        return self._arm.link

    @property
    def pose_for(self) -> PoseFor | None:
        """What turns a decided scene into a pose (`set_action_learner`), or None."""
        return self._arm.pose_for

    def set_action_learner(self, pose_for: PoseFor | None) -> None:
        """Attach what turns a detected scene into a pose: a callable
        (scene, scores, confidence) → {joint: degrees} or None, e.g. `ActionLearner.pose_for`.
        `scores` are the latest per-sense scene scores; `confidence` (percent) is the smaller of
        the two senses' probabilities for the scene. None detaches it."""
        self._arm.pose_for = pose_for

    def set_arm(self, link: Any, why_none: str = "servo: no arm attached") -> None:
        """Attach a servo link (`servant_core.servo.link`: `.arm()`, `.disarm()`, `.armed`,
        `.move_to(pose)`, `.status()`), or None to detach it (`ArmControl.set_arm`)."""
        self._arm.set_arm(link, why_none)

    def connect_arm(self, port: str | None, protocol: str, joints: Sequence[Any]) -> None:
        """Open the arm the settings name, disarmed, and attach it (`ArmControl.connect`): a
        fault is the servo's status, never raised. The engine closes it when it stops."""
        self._arm.connect(port, protocol, joints)

    def arm(self) -> None:
        """Allow the arm to move (delegates to the link); ServantError if no arm is attached."""
        self._arm.arm()

    def disarm(self) -> None:
        """Forbid the arm to move; does nothing when no arm is attached (safe to call always)."""
        self._arm.disarm()

    def read_arm_pose(self) -> dict[str, float]:
        """The arm's joints' angles as its controller reports them, armed or not (teach mode's
        "Use the arm's pose"); ServantError when there is no arm or it says nothing."""
        return self._arm.read_pose()
