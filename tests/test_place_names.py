"""Issue 41 items 2, 3 and 5: one rule for a place's name at every entry point, a label whose
write fails keeps its window, and duplicate keys in settings and teach-record files."""

from __future__ import annotations

import errno
import io
import json
import sys

import numpy as np
import pytest
from textual.widgets import Input

from servant_core.actions.records import load_records
from servant_core.cli import main
from servant_core.engine import Engine
from servant_core.engine.learning import Kept
from servant_core.errors import ServantError
from servant_core.place_names import MAX_NAME_BYTES, place_key, place_name, printable_name
from servant_core.settings import load_settings
from servant_tui.app import ServantApp
from servant_tui.screens.dialogs import ScenePrompt
from servant_tui.screens.teach import TeachScreen
from tests.test_tui_live import settle
from tests.test_tui_worker_errors import open_library, said
from tests.tui_library import write_library
from tests.tui_replay import ReplayEngine

RATE = 8000

# What the engine accepted before (issue 41 item 3), each refused now.
REFUSED = [
    "x" * 300,  # OSError: File name too long
    "é" * 33,  # 66 bytes in 33 letters
    "a\x00b",  # ValueError: embedded null byte
    "a\nb",
    "a\rb",
    "caf\x1b[2Je",
    "abc\u202edef",
    "a\ud800b",
    "a\u2028b",
    "\ue000",
    "\u200b",
    "../x",
    "/abs",
    "a/b",
    "a\\b",
    ".",
    "..",
    ".hidden",
    "",
    "   ",
    "<unknown>",
]


@pytest.mark.parametrize("name", REFUSED)
def test_a_name_the_rule_refuses_is_one_line_saying_what_to_type(name: str) -> None:
    with pytest.raises(ServantError) as refused:
        place_name(name)
    message = str(refused.value)
    assert "\n" not in message and "\r" not in message and "\x1b" not in message
    assert "instead" in message
    suggested = message.rsplit("such as ", 1)[1].removesuffix(" instead")
    assert place_name(eval(suggested)) == eval(suggested), "the suggestion is itself accepted"


def test_names_are_limited_in_bytes_not_letters() -> None:
    assert place_name("k" * MAX_NAME_BYTES) == "k" * MAX_NAME_BYTES
    assert place_name("é" * (MAX_NAME_BYTES // 2)) == "é" * (MAX_NAME_BYTES // 2)
    with pytest.raises(ServantError, match=f"at most {MAX_NAME_BYTES} bytes"):
        place_name("k" * (MAX_NAME_BYTES + 1))


def test_a_name_matching_a_known_place_is_that_place_in_its_spelling(tmp_path) -> None:
    (tmp_path / "cafe").mkdir()
    assert place_name("Cafe", tmp_path) == "cafe"
    assert place_name("  CAFE ", tmp_path) == "cafe"
    assert place_name("Ｃａｆｅ", tmp_path) == "cafe"  # fullwidth letters
    assert place_name("Street", known=["street"]) == "street"
    assert place_name("Gym", tmp_path, known=["street"]) == "Gym"
    assert place_name("cafe\u0301") == "café"  # decomposed typing, composed as a new name
    assert place_key("Straße") == place_key("STRASSE")


def test_a_file_in_the_library_is_no_place(tmp_path) -> None:
    (tmp_path / "notes.txt").write_text("mine")
    (tmp_path / "gone").symlink_to(tmp_path / "nowhere")
    for name in ("notes.txt", "NOTES.TXT", "gone"):
        with pytest.raises(ServantError, match="is a file, not a place's folder"):
            place_name(name, tmp_path)
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_printable_name_escapes_a_name_from_disk_only_when_it_would_split_a_line() -> None:
    assert printable_name("café") == "café"
    assert printable_name("a\nb") == "'a\\nb'" and "\n" not in printable_name("a\nb")
    assert "\u202e" not in printable_name("abc\u202e")


# -- the engine's label ---------------------------------------------------------------------------


def engine_with_unknown(tmp_path) -> tuple[Engine, str]:
    """An engine with no recogniser and one unknown window of sound kept for a label."""
    engine = Engine(library_root=tmp_path / "lib")
    sound = np.random.default_rng(1).uniform(-0.5, 0.5, RATE).astype(np.float32)
    return engine, engine._unknowns.keep(Kept("audio", sound, RATE))


def written(tmp_path) -> list:
    return sorted(p for p in (tmp_path / "lib").rglob("*")) if (tmp_path / "lib").exists() else []


def test_a_label_whose_write_fails_can_be_answered_again(tmp_path, monkeypatch) -> None:
    """Issue 41 item 2: the window was taken out before it was written; a full disk lost it."""
    engine, window = engine_with_unknown(tmp_path)

    def disk_full(path, data):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr("servant_core.audio.atomic_write_bytes", disk_full)
    with pytest.raises(ServantError) as failed:
        engine.label_unknown(window, "cafe")
    assert "No space left on device" in str(failed.value) and "\n" not in str(failed.value)
    monkeypatch.undo()
    path = engine.label_unknown(window, "cafe")
    assert path.parent == tmp_path / "lib" / "cafe" and path.exists()
    with pytest.raises(ServantError, match="no such unknown window"):
        engine.label_unknown(window, "cafe")


def test_a_library_that_cannot_be_written_keeps_the_window(tmp_path) -> None:
    """A real failure, no stand-in: the library's folder is a file."""
    engine, window = engine_with_unknown(tmp_path)
    (tmp_path / "blocked").write_text("mine")
    engine.library_root = tmp_path / "blocked" / "lib"
    with pytest.raises(ServantError, match="cannot be written"):
        engine.label_unknown(window, "cafe")
    engine.library_root = tmp_path / "lib"
    assert engine.label_unknown(window, "cafe").exists()


@pytest.mark.parametrize("name", ["x" * 300, "a\x00b", "a\nb", "caf\x1be", "abc\u202e", "a\ud800"])
def test_the_engine_refuses_what_the_rule_refuses_writing_nothing_losing_nothing(
    tmp_path, name
) -> None:
    engine, window = engine_with_unknown(tmp_path)
    with pytest.raises(ServantError, match="instead"):
        engine.label_unknown(window, name)
    assert written(tmp_path) == []
    assert engine.label_unknown(window, "cafe").exists()


def test_the_engine_labels_a_known_place_in_its_spelling(tmp_path) -> None:
    engine, window = engine_with_unknown(tmp_path)
    (tmp_path / "lib" / "cafe").mkdir(parents=True)
    (tmp_path / "lib" / "notes").write_text("mine")
    with pytest.raises(ServantError, match="is a file"):
        engine.label_unknown(window, "Notes")
    assert engine.label_unknown(window, "Cafe").parent == tmp_path / "lib" / "cafe"
    assert sorted(p.name for p in (tmp_path / "lib").iterdir()) == ["cafe", "notes"]


# -- teach mode and the library's relabel dialog --------------------------------------------------


async def test_teach_mode_names_a_place_by_the_rule(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("SERVANT_DATA_DIR", str(tmp_path / "data"))
    root = write_library(tmp_path / "library")
    (root / "notes.txt").write_text("mine")
    app = ServantApp(ReplayEngine(), library_root=root)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        screen = app.screen
        for typed, words in (("x" * 300, "at most 64 bytes"), ("notes.txt", "is a file")):
            screen.query_one("#new-scene", Input).value = typed
            screen.use_scene()
            await settle(pilot, lambda words=words: said(app, words))
            assert screen.scene is None
        screen.query_one("#new-scene", Input).value = "CAFE"
        screen.use_scene()
        assert screen.scene == "cafe"
    assert sorted(p.name for p in root.iterdir()) == ["cafe", "notes.txt", "street"]


async def test_the_relabel_dialog_names_a_place_by_the_rule(tmp_path) -> None:
    root = write_library(tmp_path / "library")
    app = ServantApp(ReplayEngine(), library_root=root)
    async with app.run_test(size=(100, 30)) as pilot:
        screen = await open_library(pilot, app)
        screen.query_one("#samples").focus()
        await pilot.press("r")
        await settle(pilot, lambda: isinstance(app.screen, ScenePrompt))
        app.screen.query_one(Input).value = "a\u202eb"
        await pilot.press("enter")
        await settle(pilot, lambda: said(app, "U+202E"))
        assert (root / "cafe" / "rec0.wav").exists()
        await pilot.press("r")
        await settle(pilot, lambda: isinstance(app.screen, ScenePrompt))
        app.screen.query_one(Input).value = "STREET"
        await pilot.press("enter")
        await settle(pilot, lambda: (root / "street" / "rec0.wav").exists())
    assert sorted(p.name for p in root.iterdir()) == ["cafe", "street"]


# -- servant teach ----------------------------------------------------------------------------


def test_servant_teach_asks_again_for_a_label_the_rule_refuses(monkeypatch, capsys) -> None:
    session = "caf\x1b]0;x\x07e\ncoffee\n42\nCOFFEE\n50\n" + "g" * 300 + "\ngym\n10\n\n"
    monkeypatch.setattr(sys, "stdin", io.StringIO(session + "GYM\nlibrary\n"))
    assert main(["teach", "--iterations", "20"]) == 0
    out = capsys.readouterr().out
    assert "control character U+001B" in out and "\x1b" not in out
    assert "at most 64 bytes" in out
    assert [r.scene for r in load_records()] == ["coffee", "coffee", "gym"]
    assert "never taught what to do in 'library'" in out, "a place never taught is said so"
    assert "never taught what to do in 'GYM'" not in out, "and one taught in another case is not"


# -- duplicate keys -----------------------------------------------------------------------------


def test_a_settings_file_with_a_key_twice_is_refused_naming_it(tmp_path) -> None:
    """Issue 41 item 5: the last `max_angle` won (once 400 for a shoulder limited to 90)."""
    good = load_settings(tmp_path / "none.json").to_json()
    text = json.dumps(good, indent=1).replace(
        '"max_angle": 90.0', '"max_angle": 90.0, "max_angle": 120', 1
    )
    assert text.count('"max_angle": 120') == 1
    path = tmp_path / "settings.json"
    path.write_text(text)
    with pytest.raises(ServantError) as refused:
        load_settings(path)
    assert "'max_angle'" in str(refused.value) and "\n" not in str(refused.value)
    assert path.read_text() == text


def test_a_teach_record_file_with_a_key_twice_is_refused_naming_it(tmp_path) -> None:
    path = tmp_path / "records.json"
    text = '{"format": "servant-teach-records", "version": 2, "records": [], "records": []}'
    path.write_text(text)
    with pytest.raises(ServantError, match="'records'"):
        load_records(path)
    assert path.read_text() == text


def test_a_place_named_by_hand_with_a_newline_stays_on_its_line() -> None:
    """`servant run` prints each prediction on a line; a folder made by hand as `caf\\ne` split
    it (the terminal's escaping keeps newlines, which join its lines)."""
    from servant_core.cli.live import _event_line
    from servant_core.events import AcousticPrediction, SensePrediction

    heard = _event_line(AcousticPrediction(1.0, "caf\ne", 90.0, confidence_unit="%"))
    felt = _event_line(SensePrediction(2.0, "motion", "caf\u2028e", 80.0))
    assert heard is not None and felt is not None
    assert "\n" not in heard and "'caf\\ne'" in heard
    assert "\u2028" not in felt
