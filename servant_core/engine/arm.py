"""The arm's part of the engine: the servo link, the taught poses, and moves off the senses' thread.

The link (`servant_core.servo.link`) enforces the joint limits and the speed limit and refuses to
move unless armed; this part decides *whether* to ask it: only an armed arm, only a decided scene
with a pose taught for it, only above the user's confidence threshold. A rate-limited move takes
seconds, so moves and heartbeats run on the arm's own single thread.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import TYPE_CHECKING, Any

from servant_core.engine.bus import EventBus
from servant_core.errors import ServantError
from servant_core.event_text import place
from servant_core.events import ArmState, Notice
from servant_core.fusion.elsewhere import place_probability
from servant_core.servo.calibration import clamp_pose

if TYPE_CHECKING:
    from servant_core.servo.link import ServoLink

Pose = Mapping[str, float]
PoseFor = Callable[[str, dict[str, dict[str, float]], float], Pose | None]

NO_POSE = "arm: no pose taught yet, so it stays put; teach one in teach mode (key t), then Train"


def no_pose_for(scene: str) -> str:
    """What a decided place without a taught pose means for the arm, and how to teach one."""
    return (
        f"arm: no pose was taught for {place(scene)}, so the arm stays put there; teach one with "
        "`servant teach` (then run again) or in the app's teach mode (key t)"
    )


class ArmControl:
    """The attached link (or None, with the reason as the servo's status) and what moves it."""

    def __init__(self, bus: EventBus, reopen_seconds: float) -> None:
        self.bus = bus
        self.reopen_seconds = reopen_seconds
        self.link: Any = None
        self.why_none = "servo: no arm attached; connect one with `servant servo` first"
        self._pose_for: PoseFor | None = None
        self._spec: tuple[Any, ...] | None = None  # (port, protocol, joints) of `connect`
        self._pool: ThreadPoolExecutor | None = None
        self._checked_at = 0.0
        # what was said about a place without a pose (or about no pose at all, ""): said once,
        # not at every window the place stays decided
        self._told: set[str] = set()
        self._holds: str | None = None  # the place whose pose the arm took last

    @property
    def pose_for(self) -> PoseFor | None:
        return self._pose_for

    @pose_for.setter
    def pose_for(self, pose_for: PoseFor | None) -> None:
        # a new action learner may know poses the last did not: what it lacks is said again
        self._pose_for = pose_for
        self._told.clear()

    # --- life cycle ---------------------------------------------------------------------------

    def start(self) -> None:
        """Start the arm's thread (moves, heartbeats)."""
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="servant-arm")

    def stop(self) -> None:
        """Wait for a pose being sent, then disarm and close the link `connect` opened."""
        pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True)
        self.close()

    # --- attaching ----------------------------------------------------------------------------

    def set_arm(self, link: ServoLink | None, why_none: str = "servo: no arm attached") -> None:
        """Attach a link, or None to detach it (`why_none` says why). Not closed by the engine."""
        self.link = link
        if link is None:
            self.why_none = why_none
            self.bus.report("servo", False, why_none)
        else:
            name = link.port or "link"
            self.bus.report("servo", True, f"servo: {name} attached")
        self.emit_state()

    def connect(self, port: str | None, protocol: str, joints: Sequence[Any]) -> None:
        """Open the arm the settings name (disarmed) and attach it, closing the one this method
        attached before. A missing port or a silent controller is reported as the servo's status,
        never raised. Asking again for the same port, protocol and joints keeps the link."""
        from servant_core.servo.link import ServoLink

        spec = (port, protocol, tuple(joints))
        if spec == self._spec and self.link is not None:
            return
        self.close()
        if not port:
            self.set_arm(None, "servo: no serial port set; choose the arm's port in Settings (s)")
            return
        try:
            link = ServoLink.open(port, protocol, list(joints))
        except ServantError as error:
            self.set_arm(None, str(error))
            return
        self._spec = spec
        self.set_arm(link)

    @property
    def connected_here(self) -> bool:
        """True if the link (or its absence) came from `connect`, not from `set_arm`."""
        return self.link is None or self._spec is not None

    def close(self) -> None:
        """Disarm and close the link `connect` opened, if any."""
        if self._spec is None:
            return
        link, self.link, self._spec = self.link, None, None
        if link is not None:
            try:
                link.disarm()
            finally:
                link.close()

    # --- arming -------------------------------------------------------------------------------

    def arm(self) -> None:
        """Allow the arm to move; ServantError if no arm is attached, saying why there is none
        (no such serial port, no port set, a controller that does not answer)."""
        if self.link is None:
            raise ServantError(self.why_none)
        self.link.arm()
        self._told.clear()
        self._holds = None  # armed anew, the arm goes to the next place's pose
        self.emit_state()

    def read_pose(self) -> dict[str, float]:
        """Where the controller says each joint is, armed or not (a wearer guides the arm by hand
        disarmed); ServantError if there is no arm or it reports no joint yet."""
        link = self.link
        if link is None:
            raise ServantError(f"{self.why_none}; type the angles instead")
        angles = dict(link.read_positions())
        if not angles:
            raise ServantError(
                "arm: the controller reports no joint's position yet; guide the arm, or type "
                "the angles"
            )
        return angles

    def disarm(self) -> None:
        """Forbid the arm to move; does nothing when no arm is attached (safe to call always)."""
        if self.link is not None:
            self.link.disarm()
            self.emit_state()

    def emit_state(self, pose_of: str | None = None) -> None:
        """The link's state; `pose_of` names the scene whose pose the arm has just taken."""
        state = self.link.status() if self.link is not None else None
        if isinstance(state, ArmState):
            # the link stamps its own clock; events carry the engine's
            self.bus.emit(dataclasses.replace(state, t=self.bus.clock(), pose_of=pose_of))

    # --- acting -------------------------------------------------------------------------------

    def act(
        self,
        scene: str,
        scores: dict[str, dict[str, float]],
        threshold: float | None,
        senses: Sequence[str] = ("acoustic", "visual"),
        open_senses: Collection[str] = (),
        sure: float | None = None,
    ) -> None:
        """Move to the pose taught for a decided `scene`, if armed and sure enough: `scores` are
        the senses' latest {role: {scene: probability}}; `senses` (the roles the decision rests
        on) together must give the scene and not somewhere else at least `threshold` percent
        (`place_probability`: with no sense in `open_senses`, the least sure sense's share), or
        `sure` (0–1) when the decision already says it."""
        link, pose_for, pool = self.link, self.pose_for, self._pool
        if link is None or not link.armed:
            return
        if pose_for is None:
            self._tell("", NO_POSE)
            return
        if sure is None:
            sure = place_probability(scene, scores, senses, open_senses)
        confidence = 100.0 * sure
        if threshold is not None and confidence < threshold:
            self.bus.emit(
                Notice(
                    self.bus.clock(),
                    f"arm stays put: {scene} is only {confidence:.0f} % sure, under the "
                    f"{threshold:g} % threshold (Settings)",
                )
            )
            return
        try:
            pose = pose_for(scene, scores, confidence)
        except ServantError as error:
            self.bus.error(str(error))
            return
        if pose is None:
            self._tell(scene, no_pose_for(scene))
            return
        if pool is None:  # run_until: no thread pool, send on this thread
            self._move(link, scene, dict(pose))
        else:
            pool.submit(self._move, link, scene, dict(pose))

    def _tell(self, about: str, message: str) -> None:
        if about not in self._told:
            self._told.add(about)
            self.bus.emit(Notice(self.bus.clock(), message))

    def check(self, t: float) -> None:
        """Every `reopen_seconds`, ask an armed arm where it is (on the arm's thread): a
        controller unplugged while the arm stands still would otherwise stay "ARMED" on screen
        until the next move. A lost link disarms itself; its reason becomes the servo's status."""
        link, pool = self.link, self._pool
        if link is None or pool is None or not link.armed or t < self._checked_at:
            return
        self._checked_at = t + self.reopen_seconds
        pool.submit(self._ask, link)

    def _ask(self, link: Any) -> None:
        try:
            link.read_positions()
        except ServantError as error:
            self.bus.report("servo", False, str(error))
            self.emit_state()

    def _move(self, link: Any, scene: str, pose: dict[str, float]) -> None:
        # On its own thread: a rate-limited move takes seconds and must not hold up the senses.
        moved = False
        try:
            if link.armed and _stands_at(link, pose):
                # the pose is where the arm already is: nothing to send, and nothing new to say
                # unless it now stands for another place
                if self._holds != scene:
                    self._holds = scene
                    self.bus.emit(Notice(self.bus.clock(), f"arm holds {place(scene)}'s pose"))
                return
            if link.armed:
                before = dict(link.commanded)
                link.move_to(pose)
                # not disarmed nor cut short on the way, and somewhere new: a pose the arm
                # held already, sent again at the next decision, is not a move to report
                moved = link.armed and link.at_goal and _went(before, link.commanded)
        except ServantError as error:
            self.bus.report("servo", False, str(error))
        except Exception as exc:
            self.bus.report("servo", False, f"servo: move failed ({type(exc).__name__}: {exc})")
        if moved:
            self._holds = scene
        self.emit_state(scene if moved else None)


def _stands_at(link: Any, pose: dict[str, float]) -> bool:
    """Whether the arm stands at `pose` (within the limits, as the link would aim) already: a
    pose sent again at every window the place stays decided only fills the serial line."""
    if not link.at_goal:
        return False
    aimed, _ = clamp_pose(link.joints, pose)
    return not _went(link.commanded, aimed)


def _went(before: dict[str, float], after: dict[str, float]) -> bool:
    """Whether a joint moved by half a degree or more (what a whole-degree report would show)."""
    return any(
        abs(angle - before.get(joint, float("inf"))) >= 0.5 for joint, angle in after.items()
    )
