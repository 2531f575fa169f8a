"""Checks that were missing (issue 24 item 7): folders nested without end, names too long for
the file system, a learned net that fuses what the model does not have (in
test_fusion_learned_file.py), a camera index beyond any (in test_special_files.py)."""

from __future__ import annotations

import io
from pathlib import Path

import pytest

from servant_core.audio import write_wav
from servant_core.capture.sensor_sources import sensor_sources
from servant_core.errors import ServantError
from servant_core.modelfile import load_model
from servant_core.storage import MAX_FOLDER_DEPTH, walk_files
from tests.cli_harness import assert_refused, run_cli
from tests.conftest import tone
from tests.test_cli_boundaries import SMALL_AUDIO, audio_library, picture_library


def nested(root: Path, levels: int) -> Path:
    deep = root
    deep.mkdir(parents=True, exist_ok=True)
    for _ in range(levels):  # os.makedirs recurses, and would not get there
        deep = deep / "d"
        deep.mkdir()
    return deep


@pytest.fixture
def deep_trees():
    """Removes the nested folders a test made, from the bottom up (shutil.rmtree recurses,
    and pytest's clean-up of its temporary folders would fail on them)."""
    bottoms: list[Path] = []
    yield bottoms
    for deep in bottoms:
        while deep.name == "d":
            for entry in deep.iterdir():
                if not entry.is_dir():
                    entry.unlink()
            deep.rmdir()
            deep = deep.parent


def test_walk_files_is_iterative_bounded_and_stops_at_loops(tmp_path: Path) -> None:
    (nested(tmp_path, 3) / "a.wav").write_bytes(b"x")
    (tmp_path / "d" / "loop").symlink_to(tmp_path)  # a link back up: visited once
    (tmp_path / "b.png").write_bytes(b"x")
    assert [p.relative_to(tmp_path) for p in walk_files(tmp_path)] == [
        Path("b.png"),
        Path("d/d/d/a.wav"),
    ]
    with pytest.raises(ServantError, match="more than 1 levels"):
        walk_files(tmp_path / "d", max_depth=1)


def test_a_folder_1100_levels_deep_is_one_line_everywhere(tmp_path: Path, deep_trees) -> None:
    assert MAX_FOLDER_DEPTH < 1100
    lib = audio_library(picture_library(tmp_path / "lib"))
    deep_trees.append(nested(lib / "gym", 1100))
    (deep_trees[0] / "deep.png").write_bytes((lib / "gym" / "p0.png").read_bytes())
    model = tmp_path / "m.npz"
    assert_refused(run_cli("train", str(lib), "-o", str(model), *SMALL_AUDIO), "levels deep")
    assert_refused(run_cli("eval", "image", str(lib)), "levels deep")
    assert_refused(run_cli("table", str(lib)), "levels deep")
    logs = tmp_path / "logs"
    deep_trees.append(nested(logs, 1100))
    with pytest.raises(ServantError, match="levels deep"):
        sensor_sources({"imu": str(logs)})


def test_an_output_name_too_long_for_the_file_system_is_one_line(tmp_path: Path) -> None:
    lib = audio_library(tmp_path / "lib")
    outcome = run_cli("train", str(lib), "-o", str(tmp_path / ("m" * 300 + ".npz")), *SMALL_AUDIO)
    assert_refused(outcome, "shorter name")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lib"]


def test_skip_bad_leaves_out_a_sense_whose_only_log_of_a_scene_is_bad(tmp_path: Path) -> None:
    """Issue 24 item 8: the bad file was gym's only motion log; --skip-bad aborted the whole
    train, though the recordings could train."""
    lib = audio_library(tmp_path / "lib")
    rows = "".join(f"{i * 0.01:.2f},0,0,9.8,0,0,{i % 7}\n" for i in range(300))
    (lib / "cafe" / "walk.imu.csv").write_text("time,ax,ay,az,gx,gy,gz\n" + rows)
    (lib / "gym" / "lift.imu.csv").write_text("not,a,motion,log\n1,2,3,4\n")
    model = tmp_path / "m.npz"
    assert_refused(run_cli("train", str(lib), "-o", str(model), *SMALL_AUDIO), "lift.imu.csv")
    outcome = run_cli("train", str(lib), "-o", str(model), *SMALL_AUDIO, "--skip-bad")
    assert outcome.code == 0, outcome.err
    assert "motion: not trained" in outcome.err and "acoustic:" in outcome.out
    assert set(load_model(model)) == {"acoustic"}


@pytest.mark.parametrize("typed", ["cafe\n", "\n", ""])
def test_teach_without_a_scene_taught_is_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, typed: str
) -> None:
    """Issue 24 item 8: input ending before an action, or a blank label first, exited 1."""
    monkeypatch.setattr("sys.stdin", io.StringIO(typed))
    records, learner = tmp_path / "records.json", tmp_path / "learner.npz"
    outcome = run_cli("teach", "--records", str(records), "--learner", str(learner))
    assert_refused(outcome, "nothing to learn from")
    assert not learner.exists()


def test_one_identical_picture_per_scene_is_one_line(tmp_path: Path) -> None:
    """Issue 24 item 7: fisher-bovw failed with `Found array with 0 feature(s)`."""
    lib = picture_library(tmp_path / "lib", per_scene=1)
    (lib / "gym" / "p0.png").write_bytes((lib / "cafe" / "p0.png").read_bytes())
    outcome = run_cli(
        "train", str(lib), "-o", str(tmp_path / "m.npz"), "--image-method", "fisher-bovw"
    )
    assert_refused(outcome, "no scene can be told from another")


def test_one_picture_per_scene_evaluates_or_says_why_in_one_line(tmp_path: Path) -> None:
    """Issue 24 item 7, re-probed: with one picture a scene, `eval image --method fisher-bovw`
    (the file-order split keeps each scene's only picture for training) ended in a reshape
    traceback, and `eval fusion --policy learned` in a KeyError for the scene with no test
    picture."""
    lib = picture_library(tmp_path / "lib", per_scene=1)
    outcome = run_cli("eval", "image", str(lib), "--method", "fisher-bovw")
    assert_refused(outcome, "nothing to evaluate: the file-order split keeps every picture")
    for k, scene in enumerate(("cafe", "gym")):  # recordings of three 5 s windows each
        for i in range(2):
            write_wav(lib / scene / f"r{i}.wav", tone(300 + 900 * k + 20 * i, 15.0, 8000), 8000)
    fused = run_cli(
        "eval", "fusion", str(lib), "--audio-method", "paper", "--image-method", "paper",
        "--policy", "learned", "--drop-sense", "audio",
    )  # fmt: skip
    assert fused.code == 0, fused.err
    assert "Traceback" not in fused.err
