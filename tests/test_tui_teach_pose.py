"""Teach mode's pose step on a real arm (the project's emulator on a pty, a real `ServoLink`):
the pose read while disarmed, in whole degrees; earlier samples listed and a wrong one removed;
the next place starts from empty angles (issue 22 items 5 and 6)."""

from __future__ import annotations

import time

import pytest
from textual.widgets import DataTable, Input

from servant_core.actions.records import TeachRecord, append_record, label_scores, load_records
from servant_core.engine import Engine
from servant_core.servo.calibration import angle_to_pulse
from servant_core.servo.emulator import start_emulator
from servant_core.settings import Settings, default_joints, save_settings
from servant_tui.app import ServantApp
from servant_tui.screens.teach import TeachScreen
from tests.test_tui_live import log_text, settle
from tests.test_tui_teach import type_into

GUIDED = {"shoulder": 40.0, "elbow": 20.0, "gripper": 0.0}


@pytest.fixture
def arm(tmp_path):
    """A real engine with the emulated arm attached, disarmed, the arm guided by hand to GUIDED
    (the emulator's pulses set as a servo with position feedback would report them)."""
    emulator, port = start_emulator("maestro")
    for joint in default_joints():
        pulse = angle_to_pulse(joint, GUIDED[joint.name]) - 0.1  # a pulse step off, as read back
        emulator.channel(joint.channel).aim(pulse, emulator.clock())
    save_settings(Settings(serial_port=port, protocol="maestro"))  # what Settings would hold
    engine = Engine(model_path=tmp_path / "model.npz")
    engine.connect_arm(port, "maestro", default_joints())
    yield engine
    engine.stop()
    emulator.stop()


def values(screen) -> dict[str, str]:
    return {j: screen.query_one(f"#joint-{j}", Input).value for j in GUIDED}


async def test_the_pose_step_reads_lists_and_removes_samples(tmp_path, arm):
    # as the file keeps a pose: its joints sorted by name
    pose = {"elbow": 30.0, "gripper": 5.0, "shoulder": 10.0}
    earlier = TeachRecord("street", label_scores("street"), pose, time.time())
    append_record(earlier)
    app = ServantApp(arm, library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: app.arm_state is not None and not app.arm_state.armed)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        screen = app.screen
        samples = screen.query_one("#samples", DataTable)
        assert samples.row_count == 1, "an earlier session's sample is listed"
        # in the arm's order, as this session's samples are shown (seen in a tmux walk)
        assert samples.get_row_at(0)[1] == "shoulder 10°, elbow 30°, gripper 5°"

        await type_into(pilot, "#new-scene", "cafe")
        await pilot.press("enter")
        screen.go("pose")
        await pilot.pause()
        await pilot.click("#guided")  # disarmed: the wearer guided the arm by hand
        await settle(pilot, lambda: values(screen)["shoulder"] != "")
        assert values(screen) == {"shoulder": "40", "elbow": "20", "gripper": "0"}
        assert "read the arm's pose: shoulder 40°, elbow 20°, gripper 0°" in log_text(app)

        await type_into(pilot, "#joint-shoulder", "12")  # a mistyped angle
        await pilot.click("#add-sample")
        await settle(pilot, lambda: samples.row_count == 2)
        assert [r.pose["shoulder"] for r in load_records()] == [10.0, 12.0]
        samples.focus()
        samples.move_cursor(row=1)
        await pilot.press("delete")
        await settle(pilot, lambda: samples.row_count == 1)
        assert load_records() == [earlier]
        assert "removed a sample of cafe: shoulder 12°, elbow 20°, gripper 0°" in log_text(app)

        await pilot.click("#again")
        await pilot.pause()
        assert values(screen) == {"shoulder": "", "elbow": "", "gripper": ""}
        # another scene is a new one: its name is typed next, not picked among the known
        assert screen.focused is screen.query_one("#new-scene")
