"""The demo's arm: the project's servo-controller emulator on a pty, a real `ServoLink` to it,
and an action learner taught one pose per demo scene (the paper's coffee cup, and two more).

The arm starts disarmed, as every arm does; arming it (the `a` key in the TUI) lets the demo's
decisions move it.
"""

from __future__ import annotations

import time

from servant_core.actions.learner import ActionLearner
from servant_core.actions.records import TeachRecord, label_scores
from servant_core.demo.scenes import SCENES
from servant_core.servo.emulator import ServoEmulator, start_emulator
from servant_core.servo.link import ServoLink
from servant_core.settings import default_joints

PROTOCOL = "maestro"
# degrees per joint of default_joints(): hold a cup at chest height in the café, tuck the arm
# in at the gym (ball games), keep it low and closed in the street
POSES = {
    "coffee": {"shoulder": 40.0, "elbow": 100.0, "gripper": 60.0},
    "gym": {"shoulder": 5.0, "elbow": 130.0, "gripper": 0.0},
    "street": {"shoulder": 10.0, "elbow": 20.0, "gripper": 0.0},
}


def demo_learner(random_state: int = 0) -> ActionLearner:
    """An action learner taught the demo poses, as a user would with typed labels."""
    now = time.time()
    records = [TeachRecord(s, label_scores(s, SCENES), dict(POSES[s]), now) for s in SCENES]
    # three poses, one a scene: 300 iterations bring the error to 0.001° (3,000, the default for
    # a wearer's many noisy samples, take ten times as long at the demo's start)
    return ActionLearner(max_iter=300, report_every=300, random_state=random_state).fit(records)


def start_demo_arm() -> tuple[ServoEmulator, ServoLink]:
    """The emulator on a pty and a link to it; the caller closes the link, then stops it."""
    emulator, port = start_emulator(PROTOCOL)
    try:
        link = ServoLink.open(port, PROTOCOL, default_joints())
    except BaseException:
        emulator.stop()
        raise
    return emulator, link
