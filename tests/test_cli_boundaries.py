"""Every bad input at the command line's boundary is one clear line and exit status 2
(issue 13 items 5, 6, 7, 9; issue 10 item 12), and long steps show progress."""

from __future__ import annotations

import argparse
import io
import os
import subprocess
import sys
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
import soundfile as sf

from servant_core.audio import write_wav
from servant_core.cli import build_parser
from servant_core.engine import FRESH_METHODS
from servant_core.errors import ServantError
from servant_core.library import Recording, featurize_recordings
from servant_core.progress import Progress, bar_line
from tests.cli_harness import assert_refused, run_cli, run_cli_subprocess
from tests.conftest import tone

SMALL_AUDIO = ["--audio-method", "paper", "--rate", "8000", "--window", "0.5"]


def picture_library(root: Path, per_scene: int = 3) -> Path:
    for scene, value in [("cafe", 40), ("gym", 200)]:
        (root / scene).mkdir(parents=True, exist_ok=True)
        for i in range(per_scene):
            image = np.full((16, 16, 3), value + 5 * i, np.uint8)
            image[:8] = 255 - value
            cv2.imwrite(str(root / scene / f"p{i}.png"), image)
    return root


def audio_library(root: Path, scenes=("cafe", "gym"), per_scene: int = 2) -> Path:
    for k, scene in enumerate(scenes):
        (root / scene).mkdir(parents=True, exist_ok=True)
        for i in range(per_scene):
            write_wav(root / scene / f"r{i}.wav", tone(300 + 900 * k + 20 * i, 1.0, 8000), 8000)
    return root


def png_claiming(width: int, height: int) -> bytes:
    """A small, valid PNG whose IHDR (with a correct CRC) then claims width × height."""
    ok, encoded = cv2.imencode(".png", np.zeros((4, 4, 3), np.uint8))
    data = bytearray(encoded.tobytes())
    data[16:20], data[20:24] = width.to_bytes(4, "big"), height.to_bytes(4, "big")
    data[29:33] = zlib.crc32(bytes(data[12:29])).to_bytes(4, "big")
    return bytes(data)


@pytest.fixture(scope="module")
def visual_model(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("vis")
    model = root / "model.npz"
    outcome = run_cli("train", str(picture_library(root / "lib")), "-o", str(model))
    assert outcome.code == 0, outcome.err
    return model


# Item 5: pictures.


@pytest.mark.parametrize(
    "size, word", [((40000, 40000), "megapixels"), ((9000, 9000), "megapixels")]
)
def test_a_picture_header_claiming_too_many_pixels_is_refused(tmp_path, visual_model, size, word):
    picture = tmp_path / "huge.png"
    picture.write_bytes(png_claiming(*size))  # before: cv2.error, or 243 MB for a 90-byte file
    assert_refused(run_cli("predict", str(visual_model), "--image", str(picture)), word)


def test_an_over_long_picture_name_is_one_line(tmp_path, visual_model):
    picture = tmp_path / ("p" * 300 + ".png")
    assert_refused(run_cli("predict", str(visual_model), "--image", str(picture)), "too long")


def test_skip_bad_skips_pictures_opencv_cannot_take(tmp_path):
    lib = picture_library(tmp_path / "lib")
    (lib / "gym" / "huge.png").write_bytes(png_claiming(40000, 40000))
    (lib / "cafe" / "tiff.png").write_bytes(cv2.imencode(".tiff", np.zeros((4, 4, 3)))[1])
    model = tmp_path / "m.npz"
    assert_refused(run_cli("train", str(lib), "-o", str(model)), "tiff.png")
    outcome = run_cli("train", str(lib), "-o", str(model), "--skip-bad")
    assert outcome.code == 0, outcome.err
    assert "huge.png" in outcome.err and "tiff.png" in outcome.err


# Item 6: saving.


def test_train_into_a_folder_or_a_read_only_place_is_one_line(tmp_path):
    lib = picture_library(tmp_path / "lib")
    assert_refused(run_cli("train", str(lib), "-o", str(tmp_path)), "is a folder")
    assert_refused(run_cli("train", str(lib), "-o", "/proc/servant.npz"), "cannot save")


@pytest.fixture
def never_trains(monkeypatch):
    """`servant train` fails the test if it gets as far as training."""
    import servant_core.cli.train as train

    def trained(*args):
        raise AssertionError("trained before the model's folder was checked")

    monkeypatch.setattr(train, "_train_recognisers", trained)


def test_train_into_a_file_as_a_folder_is_refused_before_training(tmp_path, never_trains):
    """A file where the model's folder should be (what root cannot write into either) is one
    line before the library is read; nothing is written."""
    lib = picture_library(tmp_path / "lib")
    notes = tmp_path / "notes.txt"
    notes.write_text("not a folder")
    for output in (notes / "model.npz", notes / "models" / "model.npz"):
        outcome = run_cli("train", str(lib), "-o", str(output))
        assert_refused(outcome, f"{notes} is a file, not a folder", "choose another place")
    assert notes.read_text() == "not a folder"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib", "notes.txt"]


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into a read-only folder")
def test_train_into_a_read_only_folder_is_refused_before_training(tmp_path, never_trains):
    lib = picture_library(tmp_path / "lib")
    kept = tmp_path / "kept"
    kept.mkdir(mode=0o500)
    try:
        outcome = run_cli("train", str(lib), "-o", str(kept / "new" / "model.npz"))
    finally:
        kept.chmod(0o700)
    assert_refused(outcome, f"the folder {kept} is not writable")
    assert list(kept.iterdir()) == []


@pytest.mark.devices
def test_a_file_size_limit_leaves_the_old_model_intact(tmp_path):
    lib = picture_library(tmp_path / "lib")
    model = tmp_path / "m.npz"
    assert run_cli("train", str(lib), "-o", str(model), "--image-method", "paper").code == 0
    before = model.read_bytes()
    # bovw's model is far larger than the paper's, and than the limit
    outcome = run_cli_subprocess("train", str(lib), "-o", str(model), file_size=len(before) + 1024)
    assert_refused(outcome, "File too large")
    assert model.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib", "m.npz"]  # no temp file left


# Item 7: option values.


@pytest.mark.parametrize(
    "argv",
    [["train", "LIB", "--window", value] for value in ("0", "-1", "nan", "inf", "1e400", "five")]
    + [["train", "LIB", "--rate", value] for value in ("0", "-1", "1e8", "44100.0", "nan")]
    + [
        ["eval", "fusion", "LIB", option, value]
        for option in ("--acoustic-window", "--confirm-window")
        for value in ("nan", "inf", "-1")
    ]
    + [["eval", "image", "LIB", "--split", value] for value in ("0", "1", "nan")]
    + [["predict", "M", "--image", "x.png", "--pictures", "0"]]
    # scikit-learn takes a random state of 32 bits: 10**30 was a traceback from the demo's fit
    + [["demo", "--headless", "--fast", "--seed", value] for value in ("-1", "2" + "0" * 30)],
)
def test_bad_option_values_are_refused_by_the_parser(argv):
    outcome = run_cli(*argv)
    assert_refused(outcome, "argument")


@pytest.mark.timeout(30)
def test_predict_on_a_fifo_does_not_wait(tmp_path, visual_model):
    fifo = tmp_path / "pipe.png"
    os.mkfifo(fifo)
    assert_refused(run_cli("predict", str(visual_model), "--image", str(fifo)), "regular file")


# Item 9: names.


def test_a_scene_folder_named_unknown_is_refused(tmp_path):
    lib = picture_library(tmp_path / "lib")
    (lib / "cafe").rename(lib / "<unknown>")
    assert_refused(run_cli("train", str(lib), "-o", str(tmp_path / "m.npz")), "<unknown>")


def test_a_scene_folder_whose_name_is_not_utf8_keeps_its_audio(tmp_path):
    lib = audio_library(tmp_path / "lib")
    (lib / "cafe").rename(lib / os.fsdecode(b"caf\xe9"))
    outcome = run_cli("train", str(lib), "-o", str(tmp_path / "m.npz"), *SMALL_AUDIO, "--json")
    assert outcome.code == 0, outcome.err
    import json

    summary = json.loads(outcome.out)
    assert summary["acoustic"]["n_windows"] == 8  # 4 recordings of two 0.5 s windows
    assert outcome.err == ""


def test_library_warnings_stay_out_of_the_output(tmp_path, capfd):
    """mpg123 (C, on descriptor 2) and scikit-learn (Python warnings) say nothing of their own."""
    lib = audio_library(tmp_path / "lib")
    signal = np.tile(tone(440, 1.0, 8000), 3)
    sf.write(tmp_path / "clip.mp3", signal, 8000, format="MP3")
    data = bytearray((tmp_path / "clip.mp3").read_bytes())
    for i in np.random.default_rng(1).integers(200, len(data), 40):
        data[i] ^= 0xFF
    (tmp_path / "garbled.mp3").write_bytes(bytes(data))
    for i in range(2):  # identical recordings: K-Means finds fewer distinct clusters than K
        write_wav(lib / "gym" / f"r{i}.wav", tone(1200, 1.0, 8000), 8000)
        write_wav(lib / "cafe" / f"r{i}.wav", tone(1200, 1.0, 8000), 8000)
    from servant_core.cli import main

    model = tmp_path / "m.npz"
    assert main(["train", str(lib), "-o", str(model), *SMALL_AUDIO]) == 0
    assert main(["predict", str(model), "--audio", str(tmp_path / "garbled.mp3")]) == 0
    captured = capfd.readouterr()
    assert "Acoustic window" in captured.out
    # libmpg123 decodes the broken frames differently from run to run: the windows they fall in
    # may be skipped, each in Servant's own one line; nothing else reaches the terminal
    lines = captured.err.splitlines()
    assert all(line.startswith("servant: warning: skipped ") for line in lines), captured.err


def test_a_damaged_stretch_loses_its_windows_not_the_recording(tmp_path):
    """Samples that are not numbers in the middle of a recording: the windows they fall in
    are NaN (to be skipped), the others are read as they are."""
    from servant_core.audio import read_audio

    signal = np.tile(tone(440, 1.0, 8000), 12)
    path = write_wav(tmp_path / "r.wav", signal, 8000)
    data = sf.read(path, dtype="float32")[0]
    data[5 * 8000 + 100 : 5 * 8000 + 200] = np.inf
    sf.write(path, data, 8000, subtype="FLOAT")
    heard = read_audio(path, 8000)
    assert len(heard) == len(signal)
    assert np.all(np.isnan(heard[5 * 8000 + 100 : 5 * 8000 + 200]))
    np.testing.assert_allclose(heard[: 5 * 8000], data[: 5 * 8000], atol=1e-6)
    sf.write(path, np.full(8000, np.nan, np.float32), 8000, subtype="FLOAT")
    with pytest.raises(ServantError, match="holds no sample that is a number"):
        read_audio(path, 8000)


# Issue 10 item 12: help, defaults, hints, messages.


def all_parsers():
    stack = [build_parser(lazy=False)]
    while stack:
        parser = stack.pop()
        yield parser
        for action in parser._actions:
            if action.choices and hasattr(action.choices, "values"):
                stack += [p for p in action.choices.values() if hasattr(p, "_actions")]


def test_every_option_has_help_and_help_shows_defaults():
    for parser in all_parsers():
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                continue  # its subcommands each carry their own help
            assert action.help, f"{parser.prog} {action.option_strings or action.dest}"
    text = run_cli("train", "--help").out
    assert "(default: 5.0)" in text and f"(default: {FRESH_METHODS['audio']})" in text


@pytest.mark.parametrize(
    "argv",
    [
        ["--help"],
        ["train", "--help"],
        ["eval", "audio", "--help"],
        ["run", "--help"],
        ["demo", "--help"],
    ],
)
def test_help_loads_none_of_the_heavy_libraries(argv):
    """Issue 22 item 14: `servant --help` took 2.2-2.6 s, importing every command's libraries;
    `servant train --help` and `run --help` 2.9 s, importing the engine to register their options
    (bench/cli_startup.py measures them)."""
    code = (
        f"import sys\nfrom servant_tui.main import main\ntry:\n    main({argv!r})\n"
        "except SystemExit:\n    pass\n"
        "print([m for m in ('numpy', 'scipy', 'sklearn', 'cv2', 'textual') if m in sys.modules])"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "usage: servant" in result.stdout and result.stdout.strip().endswith("[]"), result.stdout


def test_the_light_names_are_the_registries_names():
    """`choices` names what the command line offers without importing the classes; the
    registries beside the classes must offer the same."""
    from servant_core import choices
    from servant_core.fusion import DEFAULT_POLICY, POLICIES
    from servant_core.recognisers import ACOUSTIC_METHODS, VISUAL_METHODS

    assert set(choices.ACOUSTIC_METHOD_NAMES) == set(ACOUSTIC_METHODS)
    assert set(choices.VISUAL_METHOD_NAMES) == set(VISUAL_METHODS)
    assert set(choices.POLICY_NAMES) == set(POLICIES)
    assert choices.DEFAULT_POLICY == DEFAULT_POLICY
    assert (FRESH_METHODS["audio"], FRESH_METHODS["image"]) == (
        choices.FRESH_AUDIO_METHOD,
        choices.FRESH_IMAGE_METHOD,
    )


def test_train_defaults_to_the_engines_fresh_methods():
    args = build_parser().parse_args(["train", "LIB"])
    assert (args.audio_method, args.image_method) == (
        FRESH_METHODS["audio"],
        FRESH_METHODS["image"],
    )


def test_every_default_is_the_same_across_train_eval_predict_and_run():
    """Issue 22 item 14: `eval audio` measured the paper's method while `train` fitted
    kmeans-encoder, and `predict` fused the paper's way while `run` fused in parallel."""
    parse = build_parser().parse_args
    train, run = parse(["train", "L"]), parse(["run"])
    audio, image = parse(["eval", "audio", "L"]), parse(["eval", "image", "L"])
    fusion, predict = parse(["eval", "fusion", "L"]), parse(["predict", "M"])
    assert audio.method == train.audio_method == fusion.audio_method
    assert image.method == train.image_method == fusion.image_method
    assert predict.policy == fusion.policy == run.policy
    assert audio.window == train.window


@pytest.mark.parametrize(
    "argv, command",
    [
        (["train", "LIB", "--bogus"], "train"),
        (["eval", "audio", "LIB", "--bogus"], "eval audio"),
        (["predict", "M", "--bogus", "3"], "predict"),
        (["run", "--bogus"], "run"),
        (["servo", "move", "--bogus", "shoulder=3"], "servo move"),
        (["train", "LIB", "--audio-method", "nope"], "train"),
    ],
)
def test_a_mistyped_option_points_to_its_commands_own_help(argv, command):
    outcome = run_cli(*argv)
    assert_refused(outcome, f"servant: error: {command}: ", f"see `servant {command} --help`")


@pytest.mark.devices
def test_servant_run_arm_on_a_missing_port_says_no_such_serial_port():
    outcome = run_cli_subprocess(
        *["run", "--headless", "--no-mic", "--no-camera", "--port", "/dev/ttyNOPE", "--arm"],
        *["--duration", "0.2"],
    )
    assert_refused(outcome, "/dev/ttyNOPE: no such serial port", "--arm")


def test_predict_numbers_windows_with_their_times(tmp_path):
    library = audio_library(tmp_path / "lib")
    model = tmp_path / "m.npz"
    assert run_cli("train", str(library), "-o", str(model), *SMALL_AUDIO).code == 0
    clip = write_wav(tmp_path / "clip.wav", tone(300, 1.6, 8000), 8000)
    outcome = run_cli("predict", str(model), "--audio", str(clip))
    assert outcome.code == 0, outcome.err
    lines = outcome.out.splitlines()
    assert [line.split(":")[0] for line in lines] == [
        "Acoustic window 0 (0-0.5 s)",
        "Acoustic window 1 (0.5-1 s)",
        "Acoustic window 2 (1-1.5 s)",
    ]


def test_train_method_points_to_the_sense_options():
    outcome = run_cli("train", "LIB", "--method", "paper")
    assert_refused(outcome, "--audio-method", "--image-method")


def test_predict_on_a_missing_file_says_no_such_file(tmp_path, visual_model):
    outcome = run_cli("predict", str(visual_model), "--image", str(tmp_path / "absent.png"))
    assert_refused(outcome, "no such file")


def test_eval_recording_protocol_says_why_nothing_can_be_evaluated(tmp_path):
    lib = audio_library(tmp_path / "lib", per_scene=1)
    outcome = run_cli("eval", "audio", str(lib), "--protocol", "recording", "--rate", "8000")
    assert_refused(outcome, "leaves fewer than two scenes", "--protocol temporal")


def test_run_help_mentions_no_internals():
    text = run_cli("run", "--help").out + run_cli("demo", "--help").out
    for internal in ("servant_tui", "intercept", "engine"):
        assert internal not in text


# Progress.


def test_bar_line_counts_and_estimates():
    assert bar_line("listening", 0, 4, 0.0) == "listening [" + "." * 24 + "] 0/4"
    assert bar_line("listening", 1, 4, 10.0).endswith("1/4  0:30 left")
    assert bar_line("listening", 4, 4, 75.0).endswith("4/4  done in 1:15")


def test_a_bar_line_fits_in_one_row_of_the_terminal():
    """Issue 22 item 10: the demo's 82-character line wrapped at 80 columns, one row more per
    redraw."""
    label = "servant demo: learning the demo's places"
    wide = bar_line(label, 4, 5, 8.0)
    assert len(wide) > 79
    narrow = bar_line(label, 4, 5, 8.0, columns=80)
    assert len(narrow) <= 79 and narrow.endswith("4/5  0:02 left") and "[####" in narrow
    assert len(bar_line(label, 4, 5, 8.0, columns=40)) <= 39


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_draws_on_a_terminal_only():
    quiet = io.StringIO()
    Progress("x", quiet)(1, 2)
    assert quiet.getvalue() == ""
    terminal = Terminal()
    ticks = iter([0.0, 1.0, 2.0])
    progress = Progress("listening", terminal, interval=0.0, clock=lambda: next(ticks))
    progress(1, 2)
    progress(2, 2)
    assert terminal.getvalue().count("\r") == 2 and terminal.getvalue().endswith("done in 0:02\n")


def test_a_progress_estimate_starts_when_the_work_does():
    """The demo loads its modules, then says `(0, total)`: the pace (and the time left) is
    counted from there, not from the bar's creation (issue 22 item 10: `4/5 0:02 left` for
    15 s)."""
    terminal = Terminal()
    ticks = iter([0.0, 6.0, 7.0])  # created; (0, 4) after 6 s of loading; (1, 4) 1 s later
    progress = Progress("demo", terminal, interval=0.0, clock=lambda: next(ticks))
    progress(0, 4)
    progress(1, 4)
    assert terminal.getvalue().endswith("1/4  0:03 left")  # not 0:21 (7 s a step)


def test_featurize_reports_progress_for_every_recording_even_skipped(tmp_path):
    lib = audio_library(tmp_path / "lib")
    (lib / "gym" / "bad.wav").write_bytes(b"nothing")
    recordings = [Recording(p.parent.name, p) for p in sorted(lib.rglob("*.wav"))]
    calls: list[tuple[int, int]] = []
    featurize_recordings(
        recordings,
        lambda w: w,
        8000,
        0.5,
        on_error=lambda e: None,
        on_progress=lambda *a: calls.append(a),
    )
    assert calls == [(i, 5) for i in range(1, 6)]
