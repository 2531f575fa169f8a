"""SVG snapshots of every screen, at 80x24 (the smallest usable), 100x30 and 160x48, in a
deterministic state.

The engine is the scripted replay of `tui_replay` (fixed times, seeded spectrum), and the library
is written by the test at a fixed path, so the same pixels come out on every run. Review
`snapshot_report.html` before accepting a change with `--snapshot-update`.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from textual.widgets import Input

from servant_tui.app import ServantApp
from servant_tui.screens.dialogs import LabelPrompt
from servant_tui.screens.library import LibraryScreen
from servant_tui.screens.teach import TeachScreen
from tests.test_tui_live import settle
from tests.tui_library import write_library
from tests.tui_replay import ReplayEngine, sensing_script, unknown_scene_script

SIZES = [
    pytest.param((80, 24), id="80x24"),
    pytest.param((100, 30), id="100x30"),
    pytest.param((160, 48), id="160x48"),
]
LIBRARY = Path("/tmp/servant-snapshot-library")


@pytest.fixture
def library() -> Path:
    shutil.rmtree(LIBRARY, ignore_errors=True)
    yield write_library(LIBRARY)
    shutil.rmtree(LIBRARY, ignore_errors=True)


def replayed(app: ServantApp, then: tuple[str, ...] = (), until=None):
    async def run_before(pilot) -> None:
        await settle(pilot, lambda: app.engine.started.is_set() and app.live.scene.decisions)
        await pilot.pause()
        if then:
            await pilot.press(*then)
        if until is not None:
            await settle(pilot, lambda: until(app))
        await pilot.pause()

    return run_before


@pytest.mark.parametrize("size", SIZES)
def test_live_screen(snap_compare, size, library):
    app = ServantApp(ReplayEngine(), mode="demo", library_root=library)
    assert snap_compare(app, terminal_size=size, run_before=replayed(app))


@pytest.mark.parametrize("size", SIZES[:2])
def test_live_screen_with_motion(snap_compare, size, library):
    """Worn with the sensor board: the walk's trace, each sense's judgement, the ambient values
    and the senses the last decision leaned on (at 80x24 beside the spectrum, condensed)."""
    app = ServantApp(ReplayEngine(sensing_script()), mode="demo", library_root=library)
    until = lambda app: len(app.live.scene.decisions) == 3 and app.live.motion.trace.frames_shown  # noqa: E731
    assert snap_compare(app, terminal_size=size, run_before=replayed(app, (), until))


@pytest.mark.parametrize("size", SIZES)
def test_live_screen_armed(snap_compare, size, library):
    app = ServantApp(ReplayEngine(), mode="demo", library_root=library)
    until = lambda app: app.arm_state.armed  # noqa: E731
    assert snap_compare(app, terminal_size=size, run_before=replayed(app, ("a",), until))


@pytest.mark.parametrize("size", SIZES)
def test_help_screen(snap_compare, size, library):
    app = ServantApp(ReplayEngine(), mode="demo", library_root=library)
    assert snap_compare(app, terminal_size=size, run_before=replayed(app, ("question_mark",)))


@pytest.mark.parametrize("size", SIZES)
def test_unknown_place_prompt(snap_compare, size, library):
    app = ServantApp(ReplayEngine(unknown_scene_script()), mode="demo", library_root=library)
    until = lambda app: isinstance(app.screen, LabelPrompt)  # noqa: E731

    async def run_before(pilot) -> None:
        await replayed(app, (), until)(pilot)
        app.screen.query_one(Input).cursor_blink = False  # the same pixels whenever it is taken
        await pilot.pause()

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@pytest.mark.parametrize("size", SIZES)
def test_library_screen(snap_compare, size, library):
    app = ServantApp(ReplayEngine(), mode="demo", library_root=library)
    until = lambda app: isinstance(app.screen, LibraryScreen)  # noqa: E731
    assert snap_compare(app, terminal_size=size, run_before=replayed(app, ("l",), until))


@pytest.mark.parametrize("size", SIZES)
def test_teach_screen(snap_compare, size, library):
    app = ServantApp(ReplayEngine(), mode="demo", library_root=library)
    until = lambda app: isinstance(app.screen, TeachScreen)  # noqa: E731
    assert snap_compare(app, terminal_size=size, run_before=replayed(app, ("t",), until))


@pytest.mark.parametrize("size", SIZES)
def test_teach_pose_step(snap_compare, size, library, tmp_path, monkeypatch):
    """The pose step whole, its inputs one input high, the typed digits visible."""
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(tmp_path))  # default joints, whoever runs it
    app = ServantApp(ReplayEngine(), mode="demo", library_root=library)

    async def run_before(pilot) -> None:
        await replayed(app, ("t",), lambda app: isinstance(app.screen, TeachScreen))(pilot)
        app.screen.go("pose")
        await pilot.pause()
        await pilot.click("#joint-shoulder")
        await pilot.press(*"45")
        app.screen.query_one("#joint-shoulder", Input).cursor_blink = False
        await pilot.pause()

    assert snap_compare(app, terminal_size=size, run_before=run_before)


@pytest.mark.parametrize("size", SIZES)
def test_settings_screen(snap_compare, size, library):
    settings = pytest.importorskip(
        "servant_core.settings", reason="settings come with the servo work"
    )
    from servant_tui.screens.settings import SettingsScreen

    app = ServantApp(
        ReplayEngine(), mode="demo", library_root=library, settings=settings.Settings()
    )
    until = lambda app: isinstance(app.screen, SettingsScreen)  # noqa: E731

    async def run_before(pilot) -> None:
        await replayed(app, ("s",), until)(pilot)
        # the form opens on the audio input: its cursor the same whenever the picture is taken
        app.screen.query_one("#audio_device", Input).cursor_blink = False
        await pilot.pause()

    assert snap_compare(app, terminal_size=size, run_before=run_before)
