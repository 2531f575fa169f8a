"""One rule for a damaged file in a library, for every command that reads one (issue 39 item
10): it stops, naming the file and `--skip-bad`; with `--skip-bad` it leaves the file out with a
warning and goes on. Before, `servant train` stopped without naming the option and `servant eval
audio` skipped the file, warning; `eval image`, `eval fusion` and `table` had no `--skip-bad`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from servant_core.audio import write_wav
from servant_core.demo.audio_synth import DEMO_RATE
from servant_core.demo.scenes import SCENES, synth_window, write_demo_library
from tests.cli_harness import assert_refused, run_cli


def demo_library(root: Path) -> Path:
    """The demo's library, its recordings three windows long (two a place), so that each has
    windows to test on after the temporal split."""
    write_demo_library(root, seed=3)
    for scene in SCENES:
        for wav in (root / scene).glob("*.wav"):
            wav.unlink()
        for k in range(2):
            rng = np.random.default_rng([5, k])
            sound = np.concatenate([synth_window(scene, rng) for _ in range(3)])
            write_wav(root / scene / f"long-{k}.wav", sound, DEMO_RATE)
    return root


@pytest.fixture(scope="module")
def damaged_library(tmp_path_factory):
    """The demo's library with a recording and a picture that cannot be read."""
    root = demo_library(tmp_path_factory.mktemp("damaged") / "library")
    (root / "coffee" / "broken.wav").write_bytes(b"RIFF\x24\x00\x00\x00WAVEfmt " + bytes(40))
    (root / "coffee" / "broken.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(64))
    return root


COMMANDS = {
    "train": ["train", "{lib}", "-o", "{out}", "--audio-method", "codebook"]
    + ["--image-method", "bovw"],
    "eval audio": ["eval", "audio", "{lib}", "--method", "codebook", "--protocol", "recording"],
    "eval image": ["eval", "image", "{lib}", "--method", "bovw"],
    "eval fusion": ["eval", "fusion", "{lib}", "--audio-method", "codebook"]
    + ["--image-method", "bovw"],
    "table": ["table", "{lib}"],
}


def argv(command: str, lib, tmp_path) -> list[str]:
    return [a.format(lib=lib, out=tmp_path / "model.npz") for a in COMMANDS[command]]


@pytest.mark.parametrize("command", COMMANDS)
def test_a_damaged_file_stops_every_command_naming_it_and_skip_bad(
    command, damaged_library, tmp_path
):
    outcome = run_cli(*argv(command, damaged_library, tmp_path))
    assert_refused(outcome, "broken.", "--skip-bad")
    assert not (tmp_path / "model.npz").exists()


@pytest.mark.parametrize("command", COMMANDS)
def test_skip_bad_leaves_a_damaged_file_out_with_a_warning_for_every_command(
    command, damaged_library, tmp_path
):
    outcome = run_cli(*argv(command, damaged_library, tmp_path), "--skip-bad")
    assert outcome.code == 0, outcome.err
    warnings = outcome.err.splitlines()
    assert warnings and all(w.startswith("servant: warning: skipped ") for w in warnings), warnings
    assert any("broken." in w for w in warnings), warnings
