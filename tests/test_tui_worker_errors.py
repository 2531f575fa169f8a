"""A job a screen starts (retrain, evaluate, train, save, label) that fails reaches the user: one
line in the log, a notification, and the real reason where the screen showed the job's status.
Long jobs (retrain, evaluate) show a progress bar with an estimate of the time left."""

from __future__ import annotations

import errno
import shutil

import pytest
from textual.widgets import Input, Static

from servant_core.engine import Engine
from servant_core.errors import ServantError
from servant_core.recognisers.base import check_training_scenes
from servant_tui.app import ServantApp
from servant_tui.screens.dialogs import LabelPrompt
from servant_tui.screens.library import LibraryScreen
from servant_tui.screens.teach import TeachScreen
from servant_tui.widgets.progress import WorkProgress
from tests.test_tui_live import log_text, settle
from tests.tui_library import write_library
from tests.tui_replay import ReplayEngine, unknown_scene_script

ONE_SCENE = "training needs at least two scenes, found one (cafe); add a second scene folder"


class FittingEngine(ReplayEngine):
    """A replay whose retrain walks the library's files and checks its scenes as the real
    engine does (`Engine.retrain` featurizes every recording and picture, then fits)."""

    def retrain(self, library) -> None:
        self.walked = [item.path.name for item in [*library.recordings, *library.pictures]]
        check_training_scenes(library.scenes, len(library.scenes))
        super().retrain(library)


def one_scene_library(tmp_path):
    root = write_library(tmp_path / "library")
    shutil.rmtree(root / "street")
    return root


def status(app, selector: str) -> str:
    return str(app.screen.query_one(selector, Static).render())


def said(app, text: str) -> bool:
    return text in log_text(app) and any(text in n.message for n in app._notifications)


async def open_library(pilot, app) -> LibraryScreen:
    await pilot.press("l")
    await settle(pilot, lambda: isinstance(app.screen, LibraryScreen))
    return app.screen


async def test_library_retrain_error_reaches_status_log_and_notification(tmp_path):
    app = ServantApp(FittingEngine(), library_root=one_scene_library(tmp_path))
    async with app.run_test(size=(100, 30)) as pilot:
        await open_library(pilot, app)
        await pilot.press("R")
        await settle(pilot, lambda: said(app, ONE_SCENE))
        assert ONE_SCENE in status(app, "#library-status")
        assert "retraining" not in status(app, "#library-status")
        assert not app.screen.query_one(WorkProgress).display, "a failed job's bar goes away"


async def test_library_evaluate_error_reaches_status_log_and_notification(tmp_path):
    app = ServantApp(ReplayEngine(), library_root=one_scene_library(tmp_path))
    async with app.run_test(size=(100, 30)) as pilot:
        await open_library(pilot, app)
        await pilot.press("e")
        await settle(pilot, lambda: said(app, ONE_SCENE), tries=500)
        assert ONE_SCENE in status(app, "#library-status")


async def test_library_retrain_and_evaluate_show_progress(tmp_path):
    root = write_library(tmp_path / "library")
    engine = FittingEngine()
    app = ServantApp(engine, library_root=root)
    async with app.run_test(size=(100, 30)) as pilot:
        screen = await open_library(pilot, app)
        bar = screen.query_one(WorkProgress)
        assert not bar.display, "no bar before a job"
        await pilot.press("R")
        await settle(pilot, lambda: engine.retrained)
        await settle(pilot, lambda: bar.total == 8 and bar.progress == 8)
        assert engine.walked == ["rec0.wav", "rec1.wav"] * 2 + ["pic0.png", "pic1.png"] * 2
        assert bar.display and bar.query_one("#eta"), "the bar shows, with its estimate"

        await pilot.press("e")
        await settle(pilot, lambda: screen.evaluation is not None, tries=1000)
        # the listening, then the same bar over the folds (a model fitted and tested a fold):
        # full at the end, not full before the folds began
        await settle(pilot, lambda: bar.total is not None and bar.progress == bar.total)


async def test_library_uses_an_engines_own_progress_when_it_has_one(tmp_path):
    class ReportingEngine(ReplayEngine):
        retrain_reports_progress = True

        def retrain(self, library, on_progress=None) -> None:
            on_progress(3, 7)  # what the engine says, not a count of files
            super().retrain(library)

    engine = ReportingEngine()
    app = ServantApp(engine, library_root=write_library(tmp_path / "library"))
    async with app.run_test(size=(100, 30)) as pilot:
        screen = await open_library(pilot, app)
        await pilot.press("R")
        await settle(pilot, lambda: engine.retrained)
        bar = screen.query_one(WorkProgress)
        await settle(pilot, lambda: bar.total == 7 and bar.progress == 7)


async def test_teach_retrain_error_reaches_status_log_and_notification(tmp_path):
    app = ServantApp(FittingEngine(), library_root=one_scene_library(tmp_path))
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: app.arm_state is not None)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        app.screen.go("train")
        await pilot.pause()
        await pilot.click("#retrain")
        await settle(pilot, lambda: said(app, ONE_SCENE))
        assert ONE_SCENE in status(app, "#train-status")
        assert "retraining" not in status(app, "#train-status")


async def test_teach_train_error_reaches_status_log_and_notification(tmp_path, monkeypatch):
    monkeypatch.setenv("SERVANT_DATA_DIR", str(tmp_path / "data"))
    (tmp_path / "data" / "teach").mkdir(parents=True)
    (tmp_path / "data" / "teach" / "records.json").write_text("{not json")
    app = ServantApp(ReplayEngine(), library_root=tmp_path / "library")
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: app.arm_state is not None)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        app.screen.go("train")
        await pilot.pause()
        await pilot.click("#train-learner")
        await settle(pilot, lambda: "teach record file" in log_text(app))
        assert any("teach record file" in n.message for n in app._notifications)
        assert "teach record file" in status(app, "#train-status")


async def test_teach_recording_error_reaches_status_log_and_notification(tmp_path):
    app = ServantApp(ReplayEngine(), library_root=tmp_path / "library")  # no audio source
    async with app.run_test(size=(120, 40)) as pilot:
        await settle(pilot, lambda: app.arm_state is not None)
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        app.screen.query_one("#new-scene", Input).value = "CoffeeScene"
        await pilot.click("#use-scene")
        await pilot.pause()
        await pilot.click("#record")
        await settle(pilot, lambda: said(app, "microphone: no audio source"))
        assert "microphone: no audio source" in status(app, "#sound-status")


async def test_settings_that_cannot_be_written_are_reported_not_fatal(tmp_path, monkeypatch):
    settings = pytest.importorskip("servant_core.settings")
    from servant_tui.screens.settings import SettingsScreen

    blocker = tmp_path / "a-file"
    blocker.write_text("")
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(blocker / "config"))  # no folder can be made
    app = ServantApp(ReplayEngine(), library_root=tmp_path, settings=settings.Settings())
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("s")
        await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
        await pilot.press("ctrl+s")
        await settle(pilot, lambda: said(app, "settings: not saved"))
        assert app.is_running and isinstance(app.screen, SettingsScreen)


async def test_settings_the_engine_refuses_are_reported(tmp_path, monkeypatch):
    settings = pytest.importorskip("servant_core.settings")
    from servant_tui.screens.settings import SettingsScreen

    class RefusingEngine(ReplayEngine):
        def apply_settings(self, settings) -> None:
            raise ServantError("servo: /dev/ttyACM9 does not answer; check the port")

    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path / "config"))
    app = ServantApp(RefusingEngine(), library_root=tmp_path, settings=settings.Settings())
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("s")
        await settle(pilot, lambda: isinstance(app.screen, SettingsScreen))
        await pilot.press("ctrl+s")
        await settle(pilot, lambda: said(app, "/dev/ttyACM9 does not answer"))


async def test_a_label_the_engine_cannot_use_is_reported(tmp_path):
    class RefusingEngine(ReplayEngine):
        def label_unknown(self, window_id: str, scene: str) -> None:
            raise ServantError(f"{window_id}: no longer kept; label the next unknown place")

    app = ServantApp(RefusingEngine(unknown_scene_script()), library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, lambda: isinstance(app.screen, LabelPrompt))
        await pilot.press(*"Library", "enter")
        await settle(pilot, lambda: said(app, "window-7: no longer kept"))


async def test_a_relabel_that_cannot_move_the_file_is_reported(tmp_path, monkeypatch):
    from servant_tui.screens.dialogs import ScenePrompt

    def disk_full(source, target):
        raise OSError(errno.ENOSPC, "No space left on device")

    root = write_library(tmp_path / "library")
    app = ServantApp(ReplayEngine(), library_root=root)
    async with app.run_test(size=(100, 30)) as pilot:
        screen = await open_library(pilot, app)
        (root / "blocked").write_text("")  # a file where the new scene's folder would go
        screen.query_one("#samples").focus()
        await pilot.press("r")
        await settle(pilot, lambda: isinstance(app.screen, ScenePrompt))
        app.screen.query_one(Input).value = "blocked"
        await pilot.press("enter")
        await settle(pilot, lambda: said(app, "'blocked' in the library"))
        assert (root / "blocked").read_text() == "", "the file is left as it was"

        monkeypatch.setattr("servant_tui.screens.library.os.replace", disk_full)
        await pilot.press("r")
        await settle(pilot, lambda: isinstance(app.screen, ScenePrompt))
        app.screen.query_one(Input).value = "kitchen"
        await pilot.press("enter")
        await settle(pilot, lambda: said(app, "cannot move it to kitchen (No space left"))
        assert (root / "cafe" / "rec0.wav").exists(), "nothing lost"


async def test_teach_retrain_names_the_place_that_lacks_pictures(tmp_path):
    """Issue 22 item 7: the real engine retrained the sound and said `recognisers retrained on 2
    scenes` beside `retrain (pictures): … add a second scene folder`. It says what it retrained
    and, in teach mode's words, which place lacks pictures."""
    root = write_library(tmp_path / "library")
    for picture in (root / "street").glob("*.png"):
        picture.unlink()
    engine = Engine(model_path=tmp_path / "model.npz")
    app = ServantApp(engine, library_root=root)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        app.screen.go("train")
        await pilot.pause()
        await pilot.click("#retrain")
        await settle(pilot, lambda: "retrained on" in status(app, "#train-status"), tries=3000)
        assert status(app, "#train-status") == "sound retrained on cafe, street"
        lacking = "pictures: only cafe has any"
        await settle(pilot, lambda: said(app, lacking))
        assert said(app, "take pictures of street in teach mode (key t), then retrain")
        assert "second scene folder" not in log_text(app)
    assert engine.visual is None and engine.acoustic is not None
