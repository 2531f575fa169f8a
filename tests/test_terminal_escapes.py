"""Names from files never reach the terminal raw (issue 24 item 2): a scene folder or a model
header's scene named `ESC ] 0 ; PWNED BEL ESC [ 2 J` cannot retitle or clear the user's terminal
through `train`, `predict`, `run` or `teach`; its control characters are shown as escapes."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest

from servant_core.actions.records import TeachRecord, label_scores, save_records
from servant_core.cli import build_parser, terminal_text
from servant_core.cli.arm import run_teach
from servant_core.cli.live import _printer
from servant_core.events import AcousticPrediction, Decision, UnknownScene
from tests.cli_harness import run_cli
from tests.test_cli_boundaries import SMALL_AUDIO, audio_library

HOSTILE = "\x1b]0;PWNED\x07\x1b[2J\x9b31m"
CONTROL = [chr(c) for c in (*range(0x20), *range(0x7F, 0xA0)) if chr(c) not in "\n\t"]


def assert_inert(text: str) -> None:
    assert not [c for c in text if c in CONTROL], repr(text)


def test_terminal_text_escapes_every_control_character_but_newline_and_tab() -> None:
    assert terminal_text("a\tb\nc") == "a\tb\nc"
    assert terminal_text(HOSTILE) == "\\x1b]0;PWNED\\x07\\x1b[2J\\x9b31m"
    assert_inert(terminal_text("".join(CONTROL)))


@pytest.fixture(scope="module")
def hostile_model(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("escapes")
    lib = audio_library(root / "lib", scenes=(HOSTILE, "gym"))
    return lib, root / "model.npz"


def test_train_and_predict_escape_a_scene_folder_name(hostile_model) -> None:
    lib, model = hostile_model
    trained = run_cli("train", str(lib), "-o", str(model), *SMALL_AUDIO)
    assert trained.code == 0, trained.err
    assert "PWNED" in trained.out
    assert_inert(trained.out + trained.err)
    recording = next((lib / HOSTILE).iterdir())
    predicted = run_cli("predict", str(model), "--audio", str(recording))
    assert predicted.code == 0, predicted.err
    assert "PWNED" in predicted.out
    assert_inert(predicted.out + predicted.err)
    as_json = run_cli("predict", str(model), "--audio", str(recording), "--json")
    assert_inert(as_json.out)
    assert json.loads(as_json.out)["acoustic"][0]["scene"] in (HOSTILE, "gym", "<unknown>")


def test_run_escapes_the_scenes_of_its_events(capsys: pytest.CaptureFixture[str]) -> None:
    show = _printer(False)
    show(AcousticPrediction(1.0, HOSTILE, 90.0, confidence_unit="%"))
    show(UnknownScene(2.0, "audio", HOSTILE, "w1"))
    show(Decision(3.0, HOSTILE, 80.0, f"{HOSTILE} detected"))
    out = capsys.readouterr().out
    assert out.count("PWNED") == 3
    assert_inert(out)


def test_teach_escapes_scenes_read_from_the_records(tmp_path: Path) -> None:
    """A label holding control characters is refused as it is typed (`place_names`); one in a
    records file written before that rule, or by hand, is still shown escaped."""
    records = tmp_path / "records.json"
    save_records([TeachRecord(HOSTILE, label_scores(HOSTILE), {"shoulder": 10.0}, 1.0)], records)
    parser = build_parser()
    argv = ["teach", "--records", str(records), "--learner", str(tmp_path / "l.npz")]
    args = parser.parse_args([*argv, "--iterations", "50"])
    out = io.StringIO()
    script = f"{HOSTILE}\ngym\n80\n\n{HOSTILE}\n"
    assert run_teach(args, io.StringIO(script), out) == 0
    assert "control character U+001B" in out.getvalue()
    assert "PWNED" in out.getvalue()
    assert_inert(out.getvalue())
    again = io.StringIO()
    run_teach(parser.parse_args([*argv, "--predict-only"]), io.StringIO(f"{HOSTILE}\n"), again)
    assert_inert(again.getvalue())


def test_emulate_servo_escapes_joint_names_from_the_settings(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """The emulator names each move's joint from the user's settings, printed raw before."""
    import threading

    from servant_core.cli.arm import _say_moves
    from servant_core.servo.emulator import start_emulator
    from servant_core.servo.link import ServoLink
    from servant_core.settings import Joint

    joint = Joint(HOSTILE, 3, 0.0, 90.0, 1000.0, 1500.0, 90.0, 0.0)
    emulator, port = start_emulator("maestro")
    stop = threading.Event()
    watcher = threading.Thread(target=_say_moves, args=(emulator, [joint], stop))
    watcher.start()
    out = ""
    try:
        link = ServoLink.open(port, "maestro", [joint])
        try:
            link.arm()
            link.move_to({HOSTILE: 20.0})
        finally:
            link.close()
        for _ in range(50):
            out += capsys.readouterr().out
            if "received a move" in out:
                break
            stop.wait(0.1)
    finally:
        stop.set()
        watcher.join()
        emulator.stop()
    assert "PWNED" in out
    assert_inert(out)
