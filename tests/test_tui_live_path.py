"""The terminal app on the real engine the wearer gets (`servant` alone): a first start in empty
data and config dirs, the arm of the settings, settings and taught poses reaching the engine, and
when an unknown place may interrupt. The servo is the project's emulator on a pty; microphone and
camera are absent here (their own tests use the virtual microphone and video files)."""

from __future__ import annotations

import time

from servant_core.actions.learner import ActionLearner
from servant_core.actions.records import TeachRecord, label_scores
from servant_core.engine import NO_MODEL, Engine, LiveSettings, build_live_engine
from servant_core.events import AcousticPrediction, UnknownScene
from servant_core.fusion import FusionConfig
from servant_core.servo.emulator import start_emulator
from servant_core.settings import Settings
from servant_tui.app import ServantApp
from servant_tui.messages import TrainingDone
from servant_tui.screens.dialogs import LabelPrompt
from tests.test_tui_live import log_text, settle
from tests.tui_replay import ReplayEngine


def senseless(**user) -> Engine:
    """The live engine with neither microphone nor camera, on the given user settings."""
    return build_live_engine(LiveSettings(use_microphone=False, camera=None, user=Settings(**user)))


async def test_a_first_start_says_to_teach_two_scenes_and_why_the_arm_is_missing(tmp_path):
    app = ServantApp(senseless(), library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, lambda: "no model yet" in log_text(app))
        assert any(NO_MODEL == n.message for n in app._notifications)
        assert "no serial port set" in log_text(app)
        assert app.live.arm.problem and "Settings" in app.live.arm.problem
        assert app.check_action("toggle_arm", ()) is False


async def test_the_arm_of_the_settings_can_be_armed_with_a(tmp_path):
    """Live mode used to attach no arm at all: no Arm key, "no arm state yet"."""
    emulator, port = start_emulator("maestro")
    try:
        engine = senseless(serial_port=port)
        app = ServantApp(engine, library_root=tmp_path)
        async with app.run_test(size=(100, 30)) as pilot:
            await settle(pilot, lambda: app.arm_state is not None and app.arm_state.connected)
            assert app.check_action("toggle_arm", ()) is True
            await pilot.press("a")
            await settle(pilot, lambda: app.arm_state.armed)
            assert engine.link.armed
        assert engine.link is None  # quitting closed the port
    finally:
        emulator.stop()


async def test_settings_saved_in_the_app_reach_the_running_engine(tmp_path):
    engine = senseless()
    app = ServantApp(engine, library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, lambda: engine.running)
        app.settings = Settings(acoustic_window_s=12.0, pictures_needed=4, confidence_threshold=70)
        await settle(pilot, lambda: engine.confidence_threshold == 70)
        assert engine.fusion.config == FusionConfig(12.0, 20.0, 4, 2.0)


async def test_poses_trained_in_teach_mode_are_used_by_the_engine_at_once(tmp_path):
    engine = Engine()
    app = ServantApp(engine, library_root=tmp_path)
    records = [
        TeachRecord(s, label_scores(s, ("a", "b")), {"shoulder": 10.0 * i}, time.time())
        for i, s in enumerate(("a", "b"))
    ]
    learner = ActionLearner(max_iter=200).fit(records)
    async with app.run_test(size=(100, 30)) as pilot:
        assert engine.pose_for is None
        app.live.post_message(TrainingDone(learner))
        await settle(pilot, lambda: engine.pose_for is not None)
        assert engine.pose_for("b", {}, 99.0)["shoulder"] == learner.pose_for("b")["shoulder"]


async def test_an_unknown_place_waits_for_the_live_screen_and_does_not_nag(tmp_path):
    engine = ReplayEngine(script=[])
    app = ServantApp(engine, library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, engine.started.is_set)
        await pilot.press("t")
        await pilot.pause()
        engine.emit(UnknownScene(10.0, "audio", None, "audio-1"))
        engine.emit(UnknownScene(15.0, "audio", None, "audio-1b"))
        await pilot.pause(0.1)
        assert not isinstance(app.screen, LabelPrompt), "asked over teach mode"
        # said once, not at every window the engine would ask at
        assert log_text(app).count("unknown place (audio): asked on the live screen") == 1
        engine.emit(AcousticPrediction(16.0, "cafe", 80.0, {"cafe": 0.8}, "%"))  # walked on
        engine.emit(UnknownScene(18.0, "audio", None, "audio-1c"))  # another unknown place
        await pilot.pause(0.1)
        assert log_text(app).count("unknown place (audio): asked on the live screen") == 2
        await pilot.press("escape")
        await pilot.pause()
        engine.emit(UnknownScene(20.0, "audio", None, "audio-2"))
        await settle(pilot, lambda: isinstance(app.screen, LabelPrompt))
        await pilot.press("escape")  # not now
        await settle(pilot, lambda: not isinstance(app.screen, LabelPrompt))
        for k, t in enumerate((30.0, 60.0, 200.0)):  # within five minutes of "not now"
            engine.emit(UnknownScene(t, "audio", None, f"audio-{3 + k}"))
            await pilot.pause(0.05)
            assert not isinstance(app.screen, LabelPrompt), t
        engine.emit(UnknownScene(400.0, "audio", None, "audio-9"))
        await settle(pilot, lambda: isinstance(app.screen, LabelPrompt))


async def test_the_log_says_a_decision_once_and_silence_as_silence(tmp_path):
    """The second walk: at a café the log said `CafeScene detected (…)` every 5 s, as headless
    did before; with nothing playing into the microphone the Scene pane said `hears unknown
    place`. The log now says the decision once and that it no longer holds once the microphone
    is silent, as `servant run --headless` does; the Scene pane follows every window, and says
    silence where there is silence."""
    from tests.test_headless_lines import cafe_then_silence

    engine = cafe_then_silence()
    app = ServantApp(engine, library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        scene = app.live.scene
        await settle(pilot, lambda: log_text(app).count("hears silence") == 6, tries=3000)
        rows = {str(label): str(text) for _, label, text in scene._rows()}
        assert rows["hears"] == "silence", rows
        log = log_text(app)
        assert sum(d.scene == "coffee" for d in scene.decisions) >= 2  # each window's, shown
        assert log.count("CoffeeScene detected") == 1, log
        assert log.count("No scene detected") == 1, log
        assert "No scene detected (coffee no longer heard: silence)" in log, log
        assert "hears an unknown place" not in log, log
