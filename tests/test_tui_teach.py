"""The whole teach flow through the UI: create a scene, record from a replayed source, take a
picture, enter a pose, teach a second scene, train (the error falls), test the learnt poses."""

from __future__ import annotations

import pytest
from textual import events
from textual.widgets import ContentSwitcher, DataTable, Input, Label, Sparkline, Static

from servant_core.audio import write_wav
from servant_core.library import TEACH_WINDOWS
from servant_tui.app import ServantApp
from servant_tui.screens.teach import TeachScreen
from tests.test_tui_live import settle
from tests.tui_library import RATE, noise_recording
from tests.tui_replay import ReplayEngine

records = pytest.importorskip(
    "servant_core.actions.records", reason="teach records come with the servo work"
)


async def type_into(pilot, selector: str, text: str) -> None:
    pilot.app.screen.query_one(selector, Input).value = ""
    await pilot.click(selector)
    await pilot.press(*text)


async def teach_pose(pilot, screen, pose: dict[str, str]) -> None:
    screen.go("pose")
    await pilot.pause()
    for joint, angle in pose.items():
        await type_into(pilot, f"#joint-{joint}", angle)
    await pilot.click("#add-sample")


async def test_teach_flow_from_scene_to_tested_pose(tmp_path, monkeypatch):
    monkeypatch.setenv("SERVANT_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    root = tmp_path / "library"
    engine = ReplayEngine(window_source=noise_recording(12.0, 500.0, seed=3), audio_rate=RATE)
    app = ServantApp(engine, library_root=root)
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: engine.started.is_set() and app.arm_state is not None)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        screen = app.screen

        await type_into(pilot, "#new-scene", "CoffeeScene")
        await pilot.press("enter")
        assert screen.scene == "CoffeeScene"
        await pilot.click("#record")
        await settle(pilot, lambda: screen.windows == 1, tries=400)
        assert len(list((root / "CoffeeScene").glob("*.wav"))) == 1
        assert screen.spectrum.frames_shown >= 1, "the live spectrum shows while recording"

        await pilot.press("ctrl+n")
        await pilot.click("#take-picture")
        await settle(pilot, lambda: screen.pictures == 1)
        assert len(list((root / "CoffeeScene").glob("*.png"))) == 1

        await teach_pose(pilot, screen, {"shoulder": "30", "elbow": "100", "wrist": "90"})
        await settle(pilot, lambda: screen.query_one("#samples", DataTable).row_count == 1)

        await pilot.click("#again")
        await type_into(pilot, "#new-scene", "GymScene")
        await pilot.press("enter")
        await teach_pose(pilot, screen, {"shoulder": "80", "elbow": "20", "wrist": "10"})
        await settle(pilot, lambda: screen.query_one("#samples", DataTable).row_count == 2)
        saved = records.load_records()
        assert [(r.scene, r.pose["shoulder"]) for r in saved] == [
            ("CoffeeScene", 30.0),
            ("GymScene", 80.0),
        ]

        screen.go("train")
        await pilot.pause()
        await pilot.click("#train-learner")
        await settle(pilot, lambda: screen.learner is not None, tries=1000)
        assert len(screen.errors) > 3
        assert screen.errors[-1] < screen.errors[0], "the training error must fall"
        assert list(screen.query_one("#error-curve", Sparkline).data) == screen.errors

        predictions = screen.query_one("#predictions", DataTable)
        assert predictions.row_count == 2
        coffee = [str(c) for c in predictions.get_row("CoffeeScene")]
        assert abs(float(coffee[1].rstrip("°")) - 30.0) < 5.0

        screen.go("train")
        await pilot.pause()
        await pilot.click("#retrain")
        await settle(pilot, lambda: engine.retrained)
        assert engine.retrained[0].scenes == ["CoffeeScene"], (
            "GymScene was taught a pose, no sample"
        )


async def test_a_pose_without_angles_is_refused_in_one_line(tmp_path, monkeypatch):
    monkeypatch.setenv("SERVANT_DATA_DIR", str(tmp_path / "data"))
    engine = ReplayEngine()
    app = ServantApp(engine, library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: app.arm_state is not None)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        await type_into(pilot, "#new-scene", "CoffeeScene")
        await pilot.press("enter")
        await teach_pose(pilot, app.screen, {"shoulder": "30"})
        await settle(pilot, lambda: app._notifications)
        assert any("elbow needs an angle" in n.message for n in app._notifications)
        assert records.load_records() == []


def noise_app(tmp_path, monkeypatch) -> ServantApp:
    """The app over 12 s of replayed noise, with empty data and config dirs."""
    monkeypatch.setenv("SERVANT_DATA_DIR", str(tmp_path / "data"))
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    engine = ReplayEngine(window_source=noise_recording(12.0, 500.0, seed=3), audio_rate=RATE)
    return ServantApp(engine, library_root=tmp_path / "library")


async def teaching_a_new_scene(pilot, app) -> TeachScreen:
    """Teach mode open, a new scene named and used (the sound step shown)."""
    await settle(pilot, lambda: app.engine.started.is_set())
    await pilot.press("t")
    await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
    await type_into(pilot, "#new-scene", "CoffeeScene")
    await pilot.press("enter")
    return app.screen


async def test_enter_records_window_after_window_from_the_keyboard(tmp_path, monkeypatch):
    """A wearer on the keyboard: Enter on *Record 5 s*, and again once it is done. Disabling the
    button while it recorded took the focus away, so the second Enter recorded nothing. The step
    says how many windows teach mode asks for and how many are still to go."""
    app = noise_app(tmp_path, monkeypatch)
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await teaching_a_new_scene(pilot, app)
        asks = str(screen.query_one("#sound Label", Label).render())
        assert f"{TEACH_WINDOWS} times" in asks, asks
        screen.query_one("#record").focus()
        for k in (1, 2):
            await settle(pilot, lambda: not screen.query_one("#record").disabled)
            await pilot.press("enter")
            await settle(pilot, lambda k=k: screen.windows == k, tries=400)
            said = str(screen.query_one("#sound-status", Static).render())
            assert said.startswith(f"{k} window(s) recorded, {TEACH_WINDOWS - k} more to go;")


async def test_keys_typed_in_a_burst_after_a_step_change_reach_the_step_shown(
    tmp_path, monkeypatch
):
    """Keys arrive from a terminal in a burst: Ctrl-N to the pose step, then an angle at once.
    The app forwarded the digits to the focused control before Ctrl-N had bubbled up to the
    screen's binding, and the focus moved to the pose step only after the next refresh: the
    digits went to the hidden *Take picture* (a pose went unsaved in a tmux walk)."""
    app = noise_app(tmp_path, monkeypatch)
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await teaching_a_new_scene(pilot, app)
        screen.go("pictures")
        await pilot.pause()
        # As the terminal driver does: every key posted before any is handled.
        for key, char in (("ctrl+n", None), ("4", "4"), ("2", "2")):
            app.post_message(events.Key(key, char))
        await pilot.pause(0.5)
        assert screen.query_one(ContentSwitcher).current == "pose"
        first_joint = screen.query_one("#pose-form Input", Input)
        assert first_joint.value == "42", f"the digits went to {screen.focused!r}"


async def test_angles_and_tabs_typed_in_a_burst_each_reach_their_field(tmp_path, monkeypatch):
    """ "40", Tab, "100", Tab, "60" typed quickly (a tmux walk): the app gave the digits behind
    each Tab to the first field before the Tab, bubbling up from it, moved the focus; all went
    into the shoulder's field ("4010060")."""
    app = noise_app(tmp_path, monkeypatch)
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await teaching_a_new_scene(pilot, app)
        screen.go("pose")
        await pilot.pause()
        for key, char in (("4", "4"), ("0", "0"), ("tab", "\t"), ("9", "9"), ("tab", "\t")):
            app.post_message(events.Key(key, char))  # as the terminal driver: all before any
        app.post_message(events.Key("6", "6"))
        await pilot.pause(0.5)
        values = [screen.query_one(f"#joint-{j}", Input).value for j in ("shoulder", "elbow")]
        assert values == ["40", "9"], values
        assert screen.query_one("#joint-wrist", Input).value == "6"


async def test_every_enter_on_take_picture_takes_a_picture_however_quick(tmp_path, monkeypatch):
    """Textual ignores a button's press within 0.2 s of the last (its press animation, ended by
    a timer). A wearer pressing Enter twice quickly got one picture; in the README walk under
    load (`make test` on two workers) the timer ran late and the second picture, asked after
    the first was on the screen, was never taken. And three Enters in one burst (tmux) took one
    picture: each new picture's worker cancelled the one before it had started."""
    app = noise_app(tmp_path, monkeypatch)
    async with app.run_test(size=(120, 40)) as pilot:
        screen = await teaching_a_new_scene(pilot, app)
        await pilot.press("ctrl+n")
        await settle(pilot, lambda: app.focused is not None and app.focused.id == "take-picture")
        await pilot.press("enter", "enter")  # one after the other
        await settle(pilot, lambda: screen.pictures == 2)
        for _ in range(3):  # as the terminal driver does: all posted before any is handled
            app.post_message(events.Key("enter", "\r"))
        await settle(pilot, lambda: screen.pictures == 5)
        await pilot.pause(0.5)
        assert screen.pictures == 5
        assert len(list((tmp_path / "library" / "CoffeeScene").glob("*.png"))) == 5


async def test_a_name_typed_when_scenes_are_known_goes_into_the_new_names_field(
    tmp_path, monkeypatch
):
    """Once a scene is known, teach mode opens on the known scenes' list. A returning wearer
    typing the new place's name and Enter (the README: "press t, name it") saw nothing happen:
    the list took the letters, and Enter opened it."""
    app = noise_app(tmp_path, monkeypatch)
    (tmp_path / "library" / "cafe").mkdir(parents=True)
    write_wav(tmp_path / "library" / "cafe" / "one.wav", noise_recording(5.0, 500.0, seed=1), RATE)
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: app.engine.started.is_set())
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        screen = app.screen
        assert screen.focused.id == "known"
        app.post_message(events.Key("s", "s"))
        await pilot.pause()  # the field has the focus (in tmux it then selected the "s")
        for char in "treet":  # as the terminal driver does: all posted before any is handled
            app.post_message(events.Key(char, char))
        app.post_message(events.Key("enter", "\r"))
        await settle(pilot, lambda: screen.scene is not None)
        assert screen.scene == "street"
