"""The library screen on a real library on disk: counts, relabel, delete, retrain, evaluate."""

from __future__ import annotations

import io

from rich.console import Console
from textual.widgets import DataTable, Input, Static

from servant_core.audio import write_wav
from servant_tui.app import ServantApp
from servant_tui.screens.dialogs import Confirm, ScenePrompt
from servant_tui.screens.library import LibraryScreen, evaluation_table
from tests.test_tui_live import settle
from tests.tui_library import RATE, noise_recording, write_library
from tests.tui_replay import ReplayEngine


def rows(table: DataTable) -> list[list[str]]:
    return [[str(c) for c in table.get_row_at(i)] for i in range(table.row_count)]


async def test_library_lists_relabels_deletes_and_evaluates(tmp_path):
    root = write_library(tmp_path / "library")
    engine = ReplayEngine()
    app = ServantApp(engine, library_root=root)
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("l")
        await settle(pilot, lambda: isinstance(app.screen, LibraryScreen))
        screen = app.screen
        scenes = screen.query_one("#scenes", DataTable)
        assert rows(scenes) == [["cafe", "2", "2"], ["street", "2", "2"]]

        samples = screen.query_one("#samples", DataTable)
        samples.focus()
        samples.move_cursor(row=2)  # cafe/pic0.png, after the two recordings
        await pilot.press("r")
        await settle(pilot, lambda: isinstance(app.screen, ScenePrompt))
        app.screen.query_one(Input).value = ""
        await pilot.press(*"street", "enter")
        await settle(pilot, lambda: (root / "street" / "pic0-2.png").exists())
        assert not (root / "cafe" / "pic0.png").exists(), "relabel moves, it does not copy"
        assert rows(scenes) == [["cafe", "2", "1"], ["street", "2", "3"]]

        samples.focus()
        samples.move_cursor(row=0)
        await pilot.press("d")
        await settle(pilot, lambda: isinstance(app.screen, Confirm))
        await pilot.click("#yes")
        await settle(pilot, lambda: not (root / "cafe" / "rec0.wav").exists())
        assert rows(scenes)[0] == ["cafe", "1", "1"]

        await pilot.press("R")
        await settle(pilot, lambda: engine.retrained)
        assert engine.retrained[0].scenes == ["cafe", "street"]

        await pilot.press("e")
        await settle(pilot, lambda: screen.evaluation is not None, tries=1000)
        assert screen.evaluation["protocol"] == "temporal"
        assert set(screen.evaluation["per_class"]) == {"cafe", "street"}
        text = Console(width=80, file=io.StringIO(), record=True)
        text.print(evaluation_table(screen.evaluation))
        shown = text.export_text()
        assert "balanced accuracy" in shown and "recall street" in shown


async def test_library_says_when_it_is_empty(tmp_path):
    app = ServantApp(ReplayEngine(), library_root=tmp_path / "none")
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("l")
        await settle(pilot, lambda: isinstance(app.screen, LibraryScreen))
        assert "empty" in str(app.screen.query_one("#library-status", Static).render())


def taught_library(root, samples: int):
    """A library as teach mode leaves it: each recording one 5 s window."""
    for i, (scene, centre) in enumerate((("cafe", 500.0), ("street", 2500.0))):
        for r in range(samples):
            sound = noise_recording(5.0, centre, seed=10 * i + r)
            write_wav(root / scene / f"teach-{r}.wav", sound, RATE)
    return root


async def evaluated(pilot, app: ServantApp) -> LibraryScreen:
    """`l`, then `e`: the Library once its evaluation is done."""
    await pilot.press("l")
    await settle(pilot, lambda: isinstance(app.screen, LibraryScreen))
    screen = app.screen
    await pilot.press("e")
    await settle(pilot, lambda: screen.evaluation is not None, tries=3000)
    return screen


async def test_evaluate_on_a_taught_library_leaves_one_sample_out(tmp_path):
    """Issue 22 item 4: `nothing to evaluate: no test window or picture` on every library taught
    in the app, since each 5 s recording is one window."""
    app = ServantApp(ReplayEngine(), library_root=taught_library(tmp_path / "library", 2))
    async with app.run_test(size=(100, 30)) as pilot:
        screen = await evaluated(pilot, app)
        assert screen.evaluation["protocol"] == "recording" and screen.evaluation["n_test"] == 4
        assert "leaving one recording out" in str(screen.query_one("#library-status").render())


async def test_evaluate_after_teach_mode_tests_every_sample_beside_a_longer_recording(tmp_path):
    """Issue 39 item 5: Library `e` after teach mode, with one longer recording in the library,
    said `evaluated 3 test windows`, a recall for one place only: the later part of the longer
    recording was the test, and the 5 s samples taught were never tested."""
    root = taught_library(tmp_path / "library", 3)
    write_wav(root / "cafe" / "long.wav", noise_recording(20.0, 500.0, seed=99), RATE)
    app = ServantApp(ReplayEngine(), library_root=root)
    async with app.run_test(size=(100, 30)) as pilot:
        screen = await evaluated(pilot, app)
        assert screen.evaluation["protocol"] == "recording"
        assert screen.evaluation["n_test"] == 3 + 3 + 4  # every window of every recording
        assert set(screen.evaluation["per_class"]) == {"cafe", "street"}
        status = str(screen.query_one("#library-status").render())
        assert "evaluated 10 test windows, leaving one recording out" in status, status


async def test_evaluate_says_what_to_record_when_one_sample_a_place_is_too_few(tmp_path):
    app = ServantApp(ReplayEngine(), library_root=taught_library(tmp_path / "library", 1))
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("l")
        await settle(pilot, lambda: isinstance(app.screen, LibraryScreen))
        await pilot.press("e")
        status = app.screen.query_one("#library-status")
        await settle(pilot, lambda: "failed" in str(status.render()), tries=3000)
        assert "record another sample of cafe, street in teach mode" in str(status.render())


async def test_d_on_a_scene_says_what_it_deletes_and_end_selects_the_last_sample(tmp_path):
    """Issue 39 item 11: with a scene row selected `d` did nothing and said nothing; on the
    Samples table `End` did not move the selection, so `d` then offered the first file."""
    root = write_library(tmp_path / "library")
    app = ServantApp(ReplayEngine(), library_root=root)
    async with app.run_test(size=(100, 30)) as pilot:
        await pilot.press("l")
        await settle(pilot, lambda: isinstance(app.screen, LibraryScreen))
        screen = app.screen
        screen.query_one("#scenes", DataTable).focus()
        await pilot.press("d")
        await pilot.pause()
        assert not isinstance(app.screen, Confirm)
        said = [n.message for n in app._notifications]
        assert any("selected in Samples" in m and "cafe" in m for m in said), said
        samples = screen.query_one("#samples", DataTable)
        samples.focus()
        await pilot.press("end")
        await pilot.pause()
        assert samples.cursor_row == samples.row_count - 1
        last = screen.selected_sample()
        await pilot.press("d")
        await settle(pilot, lambda: isinstance(app.screen, Confirm))
        assert last is not None and last.name in str(app.screen.query_one(Static).render())
