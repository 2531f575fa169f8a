"""Teach mode as a new user meets it: records from `servant teach` (one angle) train in the app,
limits are checked even in the demo, focus follows the step shown, and the known scenes include
the ones the engine's recognisers know."""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest
from textual.widgets import DataTable, Input, Select

from servant_core.audio import write_wav
from servant_tui.app import ServantApp
from servant_tui.screens.teach import TeachScreen
from tests.test_tui_live import settle
from tests.test_tui_teach import teach_pose, type_into
from tests.tui_library import RATE, noise_recording
from tests.tui_replay import ReplayEngine

records = pytest.importorskip("servant_core.actions.records")
settings_module = pytest.importorskip("servant_core.settings")


@pytest.fixture(autouse=True)
def own_dirs(tmp_path, monkeypatch):
    monkeypatch.setenv("SERVANT_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))


async def open_teach(pilot, app) -> TeachScreen:
    await settle(pilot, lambda: app.arm_state is not None and app.engine.started.is_set())
    await pilot.press("t")
    await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
    return app.screen


async def test_records_of_servant_teach_with_one_angle_train_with_home_angles(tmp_path):
    scenes = ["coffee", "gym"]
    now = time.time()
    # taught in the app (full pose), then as in the README's `servant teach` (one angle)
    full = {"shoulder": 10.0, "elbow": 20.0}
    records.append_record(
        records.TeachRecord("gym", records.label_scores("gym", scenes), full, now)
    )
    records.append_record(
        records.TeachRecord(
            "coffee", records.label_scores("coffee", scenes), {"shoulder": 42.0}, now
        )
    )
    settings = settings_module.Settings()
    app = ServantApp(ReplayEngine(), library_root=tmp_path / "library", settings=settings)
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await open_teach(pilot, app)
        screen.go("train")
        await pilot.pause()
        await pilot.click("#train-learner")
        await settle(pilot, lambda: screen.learner is not None, tries=1000)
        coffee = [str(c) for c in screen.query_one("#predictions", DataTable).get_row("coffee")]
        assert all("." not in v and not v.startswith("-0") for v in coffee[1:]), coffee
        shoulder, elbow = (float(v.rstrip("°")) for v in coffee[1:3])
        assert abs(shoulder - 42.0) < 5.0
        assert abs(elbow - settings.joint("elbow").home_angle) < 5.0, "elbow stays home"


async def test_demo_refuses_a_pose_outside_the_joint_limits(tmp_path):
    app = ServantApp(ReplayEngine(), mode="demo", library_root=tmp_path / "library")
    assert app.settings is None  # the demo starts without the user's settings
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await open_teach(pilot, app)
        await type_into(pilot, "#new-scene", "coffee")
        await pilot.press("enter")
        await teach_pose(pilot, screen, {"shoulder": "50011.2", "elbow": "100", "wrist": "90"})
        refusal = "shoulder 50011.2° is outside its limits 0..90°"
        await settle(pilot, lambda: any(refusal in n.message for n in app._notifications))
        assert records.load_records() == []


async def test_pose_inputs_are_one_full_input_high(tmp_path):
    app = ServantApp(ReplayEngine(), library_root=tmp_path / "library")
    async with app.run_test(size=(80, 24)) as pilot:
        screen = await open_teach(pilot, app)
        screen.go("pose")
        await pilot.pause()
        field = screen.query_one("#joint-shoulder", Input)
        assert field.outer_size.height == 3, "a border above and below one line of text"
        assert field.content_size.height == 1


async def test_focus_follows_the_step_and_enter_acts(tmp_path):
    engine = ReplayEngine(window_source=noise_recording(12.0, 500.0, seed=3), audio_rate=RATE)
    app = ServantApp(engine, library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await open_teach(pilot, app)
        screen.query_one("#new-scene", Input).value = "coffee"
        await pilot.click("#use-scene")
        await settle(pilot, lambda: app.focused is not None and app.focused.id == "record")
        await pilot.press("enter")
        await settle(pilot, lambda: screen.windows == 1, tries=400)

        await pilot.press("ctrl+n")  # to Pictures: the focused Record button is hidden now
        await settle(pilot, lambda: app.focused is not None and app.focused.id == "take-picture")
        await pilot.press("enter")
        await settle(pilot, lambda: screen.pictures == 1)


async def test_known_scenes_include_what_the_engine_recognises(tmp_path):
    engine = ReplayEngine(script=[])
    engine.acoustic = SimpleNamespace(scenes_=["coffee", "gym", "street"])
    engine.visual = SimpleNamespace(scenes_=["coffee", "gym"])
    (tmp_path / "library" / "library-scene").mkdir(parents=True)
    app = ServantApp(engine, mode="demo", library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, engine.started.is_set)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        known = app.screen.query_one("#known", Select)
        options = [value for _, value in known._options if isinstance(value, str)]
        assert options == ["coffee", "gym", "library-scene", "street"]


def test_the_test_steps_angles_are_whole_degrees_never_minus_zero():
    """Issue 22: the Test step showed "-0.0°" for a gripper taught at 0° (the learner's output
    was a hair below zero)."""
    from servant_core.event_text import angle_text, pose_text

    assert [angle_text(a) for a in (-0.04, -0.4, 19.98, 90.0)] == ["0°", "0°", "20°", "90°"]
    assert angle_text(float("nan")) == "—"
    assert pose_text({"shoulder": 19.98, "gripper": -0.02}) == "shoulder 20°, gripper 0°"


@pytest.mark.parametrize("library_has", [[], ["street"]])
async def test_teach_mode_opens_where_the_first_answer_is_typed(tmp_path, library_has):
    """Issue 22, README step 2 ("press t, name it") from the keyboard: the focus was on the
    steps list, and a name typed at once went nowhere."""
    root = tmp_path / "library"
    for scene in library_has:
        write_wav(root / scene / "a.wav", noise_recording(5.0, 300.0, seed=1), RATE)
    app = ServantApp(ReplayEngine(script=[]), library_root=root)  # a first start: no model
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, app.engine.started.is_set)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        screen = app.screen
        await pilot.pause()
        if library_has:
            assert screen.focused is screen.query_one("#known", Select)
            await pilot.press("tab")  # past the known scenes to a new one's name
        else:
            assert screen.focused is screen.query_one("#new-scene", Input)
        await pilot.press(*"cafe", "enter")
        await settle(pilot, lambda: screen.scene == "cafe")


async def test_train_then_retrain_from_the_keyboard(tmp_path):
    """README step 3 by keyboard: Enter on Train, then Enter again retrains the recognisers
    (the screen jumped to the Test step after training, leaving Retrain out of reach)."""
    now = time.time()
    for scene, angle in (("coffee", 10.0), ("gym", 60.0)):
        records.append_record(
            records.TeachRecord(
                scene, records.label_scores(scene, ["coffee", "gym"]), {"shoulder": angle}, now
            )
        )
        write_wav(tmp_path / "library" / scene / "a.wav", noise_recording(5.0, angle * 20, 2), RATE)
    engine = ReplayEngine()
    app = ServantApp(engine, library_root=tmp_path / "library", settings=settings_module.Settings())
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await open_teach(pilot, app)
        screen.go("train")
        await pilot.pause()
        screen.query_one("#train-learner").focus()
        await pilot.press("enter")
        await settle(pilot, lambda: screen.learner is not None, tries=1000)
        await pilot.pause()
        assert screen.focused is screen.query_one("#retrain")
        await pilot.press("enter")
        await settle(pilot, lambda: engine.retrained)
        assert screen.query_one("#predictions", DataTable).row_count == 2  # Test is filled too
