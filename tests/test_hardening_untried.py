"""Issue 41's "not covered yet, to try in the same way": teach-record files of 10⁵ entries or
absurd angles, labels through `servant teach` with the names of item 3, the engine's own retrain
killed with SIGKILL, and a read-only library for a user who is not root. Each through the real
command line or the engine's API the app calls."""

from __future__ import annotations

import io
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import pytest
from textual.widgets import Input

from servant_core.actions.records import load_records
from servant_core.audio import write_wav
from servant_core.engine import Engine
from servant_core.engine.learning import Kept
from servant_core.errors import ServantError
from servant_core.modelfile import load_model
from servant_core.storage import config_dir
from servant_tui.app import ServantApp
from servant_tui.screens.teach import TeachScreen
from tests.cli_harness import assert_refused, run_cli
from tests.test_tui_live import settle
from tests.test_tui_teach import type_into
from tests.test_tui_worker_errors import said
from tests.tui_library import write_library
from tests.tui_replay import ReplayEngine

RATE = 8000
PAPER = {"audio": "paper", "image": "paper"}


def records_text(poses: list[str], scenes: int = 3) -> str:
    """A teach-record file of one record a shoulder angle (each as JSON text: `NaN` too), its
    places `s0`, `s1`, ... in turn."""
    lines = []
    for i, angle in enumerate(poses):
        scene = f"s{i % scenes}"
        scores = json.dumps({"acoustic": {scene: 1.0}, "visual": {scene: 1.0}})
        pose = f'{{"shoulder": {angle}}}'
        lines.append(f'{{"scene": "{scene}", "scores": {scores}, "pose": {pose}, "t": 1.0}}')
    body = ",\n".join(lines)
    return f'{{"format": "servant-teach-records", "version": 2, "records": [\n{body}\n]}}\n'


def teach(*argv: str, session: str = "\n"):
    """`servant teach ARGV` in this process, `session` on its stdin."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sys, "stdin", io.StringIO(session))
        return run_cli("teach", "--iterations", "2", *argv)


# -- teach-record files ---------------------------------------------------------------------------


def test_a_record_file_of_a_hundred_thousand_entries_is_one_line_and_kept(tmp_path) -> None:
    path = tmp_path / "records.json"
    path.write_text(records_text(["10"] * 100_000))
    before = path.read_bytes()
    outcome = teach("--records", str(path))
    assert_refused(outcome, str(path), "more than 20,000 records")
    assert outcome.seconds < 10, f"{outcome.seconds:.1f} s"
    assert path.read_bytes() == before


@pytest.mark.parametrize(
    "angle", ["NaN", "Infinity", "-Infinity", "1e308", "-1e308", "1e400", "361", "-1e300"]
)
def test_an_angle_no_joint_can_take_is_refused_naming_its_record(tmp_path, angle) -> None:
    """Two records at 1e308 overflowed the learner's mean into NaN: `ValueError: Input y
    contains NaN.` and a traceback. A pose is clamped to its joints' limits when taught, and no
    joint's limits reach beyond ±360 degrees: an angle past them was written by hand."""
    path = tmp_path / "records.json"
    path.write_text(records_text(["10", angle, angle]))
    before = path.read_bytes()
    outcome = teach("--records", str(path), "--dry-run", session="\ns0\n")
    assert_refused(outcome, str(path), "record 2: pose['shoulder']")
    assert path.read_bytes() == before


def test_angles_within_any_joints_range_are_learned_and_reach_the_arm_clamped(tmp_path) -> None:
    """Angles a joint's range may hold, but beyond the shoulder's 0..90: the learner learns them,
    and the dry-run arm is sent only pulses within the shoulder's (1000..1500 us)."""
    path = tmp_path / "records.json"
    path.write_text(records_text(["-360", "360", "-50", "200"], scenes=2))
    argv = ("--records", str(path), "--dry-run", "--iterations", "300")
    outcome = teach(*argv, session="\ns0\n")  # s0: -360 and -50
    assert outcome.code == 0, outcome.err
    assert "is beyond 0..90 degrees, clamped to 0" in outcome.out
    for line in outcome.out.splitlines():
        words = line.split()
        if words[:1] == ["bytes:"] and words[1] == "84" and words[2] == "03":  # shoulder target
            quarters = int(words[3], 16) | int(words[4], 16) << 7
            assert 1000 <= quarters / 4 <= 1500, line


async def test_teach_mode_with_unreadable_settings_refuses_an_angle_that_is_no_number(
    tmp_path,
) -> None:
    """With settings.json unreadable, teach mode checks typed angles against no limits; `nan`
    reached the record file's own check, whose ValueError was not a ServantError, and the
    Add sample handler raised it: the app closed with a traceback."""
    config_dir().mkdir(parents=True, exist_ok=True)
    (config_dir() / "settings.json").write_text("{ not json")
    root = write_library(tmp_path / "library")
    app = ServantApp(ReplayEngine(), library_root=root)
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.press("t")
        await settle(pilot, lambda: isinstance(app.screen, TeachScreen))
        screen = app.screen
        await type_into(pilot, "#new-scene", "cafe")
        await pilot.press("enter")
        screen.go("pose")
        await pilot.pause()
        joints = [field.id for field in screen.query(Input) if str(field.id).startswith("joint-")]
        assert joints, "the replayed arm's joints are asked for"
        for joint in joints:
            screen.query_one(f"#{joint}", Input).value = "nan"
        await pilot.click("#add-sample")
        await settle(pilot, lambda: said(app, "was not added"))
        assert app.is_running
    assert load_records() == []


# -- names through `servant teach` -----------------------------------------------------------------

# Issue 3's names that reach a teach session on a line: too long, NUL, CR, ESC, a reversing mark,
# a line separator, a lone surrogate (what undecodable input becomes), a path, a dot, the unknown.
BAD_NAMES = ["x" * 300, "a\x00b", "caf\re", "caf\x1b[2Je", "abc\u202edef", "a\u2028b", "a\udcffb"]
BAD_NAMES += ["../x", "/abs", "a\\b", ".hidden", "..", "<unknown>"]


def test_servant_teach_refuses_each_bad_name_and_asks_again() -> None:
    session = "cafe\n10\n" + "".join(f"{name}\n" for name in BAD_NAMES) + "kitchen\n20\n"
    outcome = teach(session=session + "CAFE\n30\n\n")
    assert outcome.code == 0, outcome.err
    refusals = [line for line in outcome.out.splitlines() if line.endswith(" instead")]
    assert len(refusals) == len(BAD_NAMES), outcome.out
    printed = outcome.out.replace("\n", "")
    assert not [
        c for c in printed if ord(c) < 32 or c in "\u202e\u2028" or "\ud800" <= c <= "\udfff"
    ]
    assert [r.scene for r in load_records()] == ["cafe", "kitchen", "cafe"]


@pytest.mark.devices
def test_servant_teach_reads_bytes_that_are_no_utf8_as_a_name_it_refuses(tmp_path) -> None:
    """Through the real stdin: bytes that are not UTF-8 (an encoded surrogate, a Latin-1 name)."""
    code = "import sys; from servant_core.cli import main; sys.exit(main(sys.argv[1:]))"
    session = b"a\xed\xa0\x80b\ncaf\xe9\n\xff\xfe\ncafe\n10\n\n"
    proc = subprocess.run(
        [sys.executable, "-c", code, "teach", "--iterations", "2"],
        input=session,
        capture_output=True,
        timeout=60,
        env={**os.environ, "SERVANT_DATA_DIR": str(tmp_path / "data")},
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = proc.stdout.decode("utf-8")  # what it prints is UTF-8, whatever it was given
    assert out.count("a lone surrogate") == 3, out
    assert [r.scene for r in load_records(tmp_path / "data" / "teach" / "records.json")] == ["cafe"]


# -- the engine's retrain killed -----------------------------------------------------------------


def small_library(root: Path) -> Path:
    """Two places, two 12 s recordings and three pictures each: a retrain of the paper's
    methods takes a fraction of a second."""
    rng = np.random.default_rng(0)
    for i, scene in enumerate(("cafe", "street")):
        for r in range(2):
            sound = (0.1 * (i + 1) * rng.standard_normal(12 * RATE)).astype(np.float32)
            write_wav(root / scene / f"rec{r}.wav", sound, RATE)
        for p in range(3):
            picture = np.full((32, 32, 3), (40 + 80 * i, 60, 120), np.uint8)
            picture[: 8 * (p + 1)] = 255
            cv2.imwrite(str(root / scene / f"pic{p}.png"), picture)
    return root


RETRAINING = """
import os, sys, time
from pathlib import Path
from servant_core.engine import Engine
library, model, hold = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3] == "hold"
if hold:  # stop where the model is written whole but not yet in place: the kill lands there
    replace = os.replace
    def held(source, target):
        if str(source).endswith(".tmp"):
            print("saving", flush=True)
            time.sleep(120)
        replace(source, target)
    os.replace = held
paper = {"audio": "paper", "image": "paper"}
engine = Engine(library_root=library, model_path=model, fresh_methods=paper)
print("ready", flush=True)
while True:
    engine.retrain(library)
"""


def retraining(library: Path, model: Path, hold: bool) -> subprocess.Popen:
    child = subprocess.Popen(
        [sys.executable, "-c", RETRAINING, str(library), str(model), "hold" if hold else "go"],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"},
    )
    assert child.stdout is not None and child.stdout.readline() == "ready\n"
    return child


def temporaries(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


@pytest.mark.devices
def test_a_retrain_killed_while_saving_keeps_the_model_and_its_temporary_goes(tmp_path) -> None:
    """SIGKILL runs no clean-up: a retrain killed mid-save left `.model.npz.XXXXXXXX.tmp`, and
    the next save removed only temporaries an hour old. Now the next save removes any that no
    living writer holds."""
    library = small_library(tmp_path / "library")
    model = tmp_path / "models" / "model.npz"
    engine = Engine(library_root=library, model_path=model, fresh_methods=PAPER)
    engine.retrain(library)
    saved = model.read_bytes()
    child = retraining(library, model, hold=True)
    try:
        assert child.stdout is not None and child.stdout.readline() == "saving\n"
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(30)
    assert model.read_bytes() == saved and load_model(model)
    assert len(temporaries(model.parent)) == 1, "killed with its model written, not in place"
    engine.retrain(library)  # the next save
    assert temporaries(model.parent) == []
    assert set(load_model(model)) == {"acoustic", "visual"}


@pytest.mark.devices
def test_a_retrain_killed_at_random_moments_always_leaves_a_model_that_loads(tmp_path) -> None:
    library = small_library(tmp_path / "library")
    model = tmp_path / "models" / "model.npz"
    moments = random.Random(41)
    for _ in range(2):
        child = retraining(library, model, hold=False)
        time.sleep(moments.uniform(0.0, 2.0))
        child.send_signal(signal.SIGKILL)
        child.wait(30)
        if model.exists():
            assert set(load_model(model)) == {"acoustic", "visual"}
    Engine(library_root=library, model_path=model, fresh_methods=PAPER).retrain(library)
    assert temporaries(model.parent) == [] and load_model(model)


# -- a read-only library --------------------------------------------------------------------------


def another_user() -> tuple[int, int] | None:
    """(uid, gid) of `nobody` for a test run by root, None for one run by another user."""
    if os.geteuid() != 0:
        return None
    import pwd

    try:
        nobody = pwd.getpwnam("nobody")
    except KeyError:
        pytest.skip("root, and no user 'nobody' to run as")
    return nobody.pw_uid, nobody.pw_gid


def as_user(user: tuple[int, int] | None, work) -> list:
    """`work()`'s answer (a JSON value), by this user, or by `user` in a forked child (every
    module the work needs loaded first: root's Python may lie in a folder the user cannot
    read)."""
    if user is None:
        return work()
    reading, writing = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child never returns into pytest
        status = 1
        try:
            os.close(reading)
            os.setgroups([])
            os.setgid(user[1])
            os.setuid(user[0])
            os.write(writing, json.dumps(work()).encode())
            status = 0
        finally:
            os._exit(status)
    os.close(writing)
    with os.fdopen(reading, "rb") as pipe:
        answer = pipe.read()
    _, status = os.waitpid(pid, 0)
    assert status == 0 and answer, f"the child running as {user} failed"
    return json.loads(answer)


def test_a_read_only_library_refuses_a_label_in_one_line_and_keeps_the_window() -> None:
    """The library's folders are another's, this user may only read them: a label is one
    ServantError naming the folder and the reason, nothing is written, and the same window
    can be labelled once there is a library this user may write (`nobody` for root, who may
    write anywhere)."""
    user = another_user()
    base = Path(tempfile.mkdtemp(prefix="servant-read-only-"))  # not in root's private tmp
    try:
        library = small_library(base / "library")
        own = base / "own"
        own.mkdir()
        if user is not None:
            os.chown(own, *user)
        for folder in (base, library, *library.iterdir()):
            folder.chmod(0o755 if user is not None else 0o555)
        before = sorted(str(p) for p in library.rglob("*"))
        warm = Engine(library_root=base / "warm-up")  # what a label needs, loaded by this user
        warm.label_unknown(warm._unknowns.keep(Kept("image", np.zeros((8, 8, 3), np.uint8))), "x")

        def work() -> list:
            engine = Engine(library_root=library)
            rng = np.random.default_rng(1)
            sound = rng.uniform(-0.5, 0.5, RATE).astype(np.float32)
            windows = [
                engine._unknowns.keep(Kept("audio", sound, RATE)),
                engine._unknowns.keep(Kept("image", rng.integers(0, 255, (24, 32, 3), np.uint8))),
            ]
            said = []
            for window in windows:
                for place in ("cafe", "kitchen"):
                    try:
                        engine.label_unknown(window, place)
                        said.append(f"{window} written into {place}")
                    except ServantError as error:
                        said.append(str(error))
            engine.library_root = own
            return [said, [engine.label_unknown(w, "cafe").is_file() for w in windows]]

        said, labelled_later = as_user(user, work)
        for line in said:
            assert "Permission denied" in line and "\n" not in line, line
        assert any(f"cannot be written to {library / 'kitchen'}" in line for line in said)
        assert labelled_later == [True, True]
        assert sorted(str(p) for p in library.rglob("*")) == before
    finally:
        for folder in (base, *base.rglob("*")):
            if folder.is_dir() and not folder.is_symlink():
                folder.chmod(0o755)
        shutil.rmtree(base, ignore_errors=True)
