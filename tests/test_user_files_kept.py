"""Options that name a file never destroy one the user has there (issue 24 item 1).

`--link` replaces only a link; `-o` and the learner's file replace only a file of their own
kind, never follow or replace a symbolic link, never take a name a scene library reads, and a
model written over keeps its permissions.
"""

from __future__ import annotations

import io
import os
import stat
import sys
import time
from pathlib import Path
from unittest import mock

import pytest

from servant_core.actions.learner import ActionLearner
from servant_core.actions.records import TeachRecord, label_scores
from servant_core.errors import ServantError
from servant_core.pty_port import PtyPort
from servant_core.storage import atomic_write_bytes
from tests.cli_harness import Outcome, assert_clear, assert_refused, run_cli
from tests.test_cli_boundaries import SMALL_AUDIO, audio_library

PRECIOUS = b"the user's own words\n"


@pytest.mark.parametrize("command", ["emulate-servo", "emulate-sensors"])
def test_link_refuses_an_existing_file_and_keeps_it(tmp_path: Path, command: str) -> None:
    precious = tmp_path / "precious.txt"
    precious.write_bytes(PRECIOUS)
    outcome = run_cli(command, "--link", str(precious), "--seconds", "0.1")
    assert_refused(outcome, "precious.txt", "not a link")
    assert precious.read_bytes() == PRECIOUS and not precious.is_symlink()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["precious.txt"]


def test_link_replaces_a_stale_link_and_removes_its_own(tmp_path: Path) -> None:
    link = tmp_path / "arm"
    link.symlink_to(tmp_path / "gone")
    (tmp_path / ".arm.tmp").write_bytes(PRECIOUS)  # the old fixed temporary name: not touched
    port = PtyPort(link)
    try:
        assert os.readlink(link) == port.device
    finally:
        port.close()
    assert not link.is_symlink()
    assert (tmp_path / ".arm.tmp").read_bytes() == PRECIOUS


def test_link_refuses_a_folder(tmp_path: Path) -> None:
    with pytest.raises(ServantError, match="not a link"):
        PtyPort(tmp_path)
    assert tmp_path.is_dir()


@pytest.fixture(scope="module")
def lib(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return audio_library(tmp_path_factory.mktemp("kept") / "lib")


def train(lib: Path, output: Path):
    return run_cli("train", str(lib), "-o", str(output), *SMALL_AUDIO)


def test_output_refuses_a_recording_of_the_library(lib: Path) -> None:
    recording = lib / "cafe" / "r0.wav"
    before = recording.read_bytes()
    assert_refused(train(lib, recording), "r0.wav", "audio")
    assert recording.read_bytes() == before


def test_output_refuses_a_library_name_not_yet_there(lib: Path, tmp_path: Path) -> None:
    assert_refused(train(lib, tmp_path / "new.png"), "new.png", ".npz")
    assert not (tmp_path / "new.png").exists()


def test_output_refuses_a_file_that_is_not_a_model(lib: Path, tmp_path: Path) -> None:
    precious = tmp_path / "notes.npz"
    precious.write_bytes(PRECIOUS)
    assert_refused(train(lib, precious), "notes.npz", "not a model file")
    assert precious.read_bytes() == PRECIOUS


def test_output_refuses_a_symlink_and_leaves_both_ends(lib: Path, tmp_path: Path) -> None:
    model = tmp_path / "model.npz"
    assert train(lib, model).code == 0
    before = model.read_bytes()
    link = tmp_path / "link.npz"
    link.symlink_to(model)
    assert_refused(train(lib, link), "symbolic link", str(model))
    assert link.is_symlink() and os.readlink(link) == str(model)
    assert model.read_bytes() == before


def test_a_model_written_over_keeps_its_permissions(lib: Path, tmp_path: Path) -> None:
    model = tmp_path / "model.npz"
    outcome = train(lib, model)
    assert_clear(outcome)
    model.chmod(0o644)
    assert train(lib, model).code == 0  # a model of its own kind: replaced, as before
    assert stat.S_IMODE(model.stat().st_mode) == 0o644
    model.chmod(0o640)
    atomic_write_bytes(model, model.read_bytes())
    assert stat.S_IMODE(model.stat().st_mode) == 0o640


def test_a_read_only_model_or_learner_is_not_written_over(lib: Path, tmp_path: Path) -> None:
    """`chmod a-w model.npz` protects a model: replacing it by rename never asked the file, so
    `train -o` wrote over it (and kept it read-only)."""
    model, learner = tmp_path / "model.npz", tmp_path / "learner.npz"
    assert train(lib, model).code == 0
    _taught_learner().save(learner)
    for path in (model, learner):
        path.chmod(0o444)
    model_bytes, learner_bytes = model.read_bytes(), learner.read_bytes()
    assert_refused(train(lib, model), "model.npz", "read-only", "chmod u+w")
    with pytest.raises(ServantError, match="read-only"):
        _taught_learner().save(learner)
    assert model.read_bytes() == model_bytes and learner.read_bytes() == learner_bytes
    model.chmod(0o644)
    assert train(lib, model).code == 0


def test_the_action_learner_refuses_a_file_that_is_not_one(tmp_path: Path) -> None:
    records = [
        TeachRecord(scene, label_scores(scene, ["cafe", "gym"]), {"shoulder": angle}, 0.0)
        for scene, angle in [("cafe", 10.0), ("gym", 80.0)] * 2
    ]
    learner = ActionLearner(max_iter=20).fit(records)
    precious = tmp_path / "learner.npz"
    precious.write_bytes(PRECIOUS)
    with pytest.raises(ServantError, match="not an action learner file"):
        learner.save(precious)
    assert precious.read_bytes() == PRECIOUS
    learner.save(tmp_path / "fresh.npz")
    learner.save(tmp_path / "fresh.npz")  # its own kind: replaced


def _taught_learner() -> ActionLearner:
    records = [
        TeachRecord(scene, label_scores(scene, ["cafe", "gym"]), {"shoulder": angle}, 0.0)
        for scene, angle in [("cafe", 10.0), ("gym", 80.0)] * 2
    ]
    return ActionLearner(max_iter=20).fit(records)


def test_a_model_and_an_action_learner_never_replace_each_other(lib: Path, tmp_path: Path) -> None:
    """Both are Servant `.npz` files: `teach --learner model.npz` once replaced a trained model
    with a learner, and `train -o learner.npz` the taught learner with a model."""
    model, learner = tmp_path / "model.npz", tmp_path / "learner.npz"
    assert train(lib, model).code == 0
    _taught_learner().save(learner)
    model_bytes, learner_bytes = model.read_bytes(), learner.read_bytes()
    with pytest.raises(ServantError, match="not an action learner file"):
        _taught_learner().save(model)
    assert_refused(train(lib, learner), "learner.npz", "not a model file")
    assert model.read_bytes() == model_bytes and learner.read_bytes() == learner_bytes


def teach(tmp_path: Path, records: Path, learner: Path, script: str) -> Outcome:
    argv = ["teach", "--dry-run", "--records", str(records), "--learner", str(learner)]
    with mock.patch.object(sys, "stdin", io.StringIO(script)):
        return run_cli(*argv, "--iterations", "20")


def test_teach_keeps_a_records_link_and_a_read_only_records_file(tmp_path: Path) -> None:
    """`teach --records link.json` replaced the link with a file; a read-only record file was
    written over; and a learner destination that would be refused was found only after the
    whole session was taught (and its records written)."""
    records, learner = tmp_path / "records.json", tmp_path / "learner.npz"
    assert teach(tmp_path, records, learner, "cafe\n10\ngym\n80\n\n").code == 0
    before = records.read_bytes()
    link = tmp_path / "link.json"
    link.symlink_to(records)
    outcome = teach(tmp_path, link, tmp_path / "l2.npz", "office\n30\n\n")
    assert_refused(outcome, "link.json", "symbolic link")
    assert link.is_symlink() and records.read_bytes() == before
    records.chmod(0o444)
    outcome = teach(tmp_path, records, tmp_path / "l3.npz", "office\n30\n\n")
    assert_refused(outcome, "records.json", "read-only")
    assert records.read_bytes() == before
    records.chmod(0o644)
    model = tmp_path / "model.npz"
    model.write_bytes(PRECIOUS)
    outcome = teach(tmp_path, records, model, "office\n30\n\n")
    assert_refused(outcome, "model.npz", "not an action learner file")
    assert "Scene label" not in outcome.out  # refused before the session
    assert records.read_bytes() == before and model.read_bytes() == PRECIOUS


def test_a_save_removes_the_temporaries_a_killed_save_left(tmp_path: Path) -> None:
    """Issue 24 item 8: a kill during a save left `.model.npz.XXXXXXXX.tmp`, and nothing ever
    removed it. The next save of that file removes those no writer holds (issue 41: a killed
    writer's, at once, not an hour later) and those an hour old; a write going on now (its
    writer holds it locked) and files of other names are kept."""
    import fcntl

    model = tmp_path / "model.npz"
    stale, killed = tmp_path / ".model.npz.ab12cd34.tmp", tmp_path / ".model.npz.ij90kl12.tmp"
    fresh = tmp_path / ".model.npz.ef56gh78.tmp"
    other = tmp_path / ".model.npz.my-own-notes.tmp"
    for path in (stale, killed, fresh, other):
        path.write_bytes(PRECIOUS)
    hours_ago = time.time() - 7200
    os.utime(stale, (hours_ago, hours_ago))
    os.utime(other, (hours_ago, hours_ago))
    with fresh.open("rb") as writing:
        fcntl.flock(writing, fcntl.LOCK_EX)  # as a writer does while it writes
        atomic_write_bytes(model, b"model")
    assert not stale.exists() and not killed.exists()
    assert fresh.read_bytes() == PRECIOUS and other.read_bytes() == PRECIOUS
    assert model.read_bytes() == b"model"
