"""Fuzz (issue 24): the classes of input the first fuzz suite did not generate.

- options naming a file the user has: `-o` and `--link` over recordings, documents, symlinks,
  folders and library names; the user's file is never changed;
- names with control characters in scene folders and model headers: never printed raw;
- numbers beyond float range and finite values that overflow inside the features: sensor log
  rows, board lines and float WAV samples from the extremes of every type;
- special files (FIFOs, links to /dev/zero, folders, dangling links) wherever a file is read;
- (issue 41) names given to a place, writes that fail while a label is written, keys given
  twice in a settings or teach-record file given to a command, and taught angles of any size.

Every case ends in success or one `servant: error:` line, in bounded time. About 2,000 cases a
run (SERVANT_FUZZ_SCALE scales them), in-process.
"""

from __future__ import annotations

import errno
import io
import json
import math
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf
from hypothesis import assume, given
from hypothesis import strategies as st

from servant_core.actions.learner import ActionLearner
from servant_core.actions.records import label_scores, load_records
from servant_core.capture.sample_files import read_sample_csv
from servant_core.capture.sensors import CHANNEL_LIMITS, CHANNELS, parse_line
from servant_core.engine import Engine
from servant_core.engine.learning import Kept
from servant_core.errors import ServantError
from servant_core.library import SceneLibrary
from servant_core.place_names import place_key, place_name
from servant_core.servo.calibration import clamp_pose
from servant_core.settings import default_joints
from tests.cli_harness import assert_clear, assert_refused, run_cli
from tests.test_fuzz_files import Workspace, fuzz, mutated_model
from tests.test_fuzz_settings import (
    beyond_floats,
    given_twice,
    parsed_values,
)
from tests.test_hardening_untried import records_text
from tests.test_terminal_escapes import CONTROL

SMALL = ["--rate", "8000", "--window", "0.5", "--audio-method", "paper", "--image-method", "paper"]


@pytest.fixture(scope="module")
def ws(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    return Workspace(tmp_path_factory.mktemp("fuzz24"))


@pytest.fixture(scope="module", autouse=True)
def models_unchanged(ws: Workspace):
    """Nothing the fuzzing does may touch the models it reads."""
    yield
    assert ws.model.read_bytes() == ws.good_model


# Options that name a user's file (item 1).

TARGETS = ["recording", "picture", "document", "link-to-model", "link-to-document", "dangling"]
TARGETS += ["folder", "library-name", "model", "fresh"]


def make_target(ws: Workspace, kind: str, name: str) -> Path:
    """A file of `kind` at a fresh path: what a user may have where an option points."""
    folder = ws.root / "targets"
    folder.mkdir(exist_ok=True)
    path = folder / f"{name}-{kind}"
    for old in folder.iterdir():
        if old.is_symlink() or old.is_file():
            old.unlink()
    if kind == "recording":
        path = path.with_suffix(".wav")
        path.write_bytes(ws.good_wav.read_bytes())
    elif kind == "picture":
        path = path.with_suffix(".png")
        path.write_bytes(ws.good_png.read_bytes())
    elif kind == "document":
        path.write_bytes(b"my notes\n")
    elif kind == "link-to-model":
        path.symlink_to(ws.model)
    elif kind == "link-to-document":
        (folder / "notes.txt").write_bytes(b"my notes\n")
        path.symlink_to(folder / "notes.txt")
    elif kind == "dangling":
        path.symlink_to(folder / "nowhere")
    elif kind == "folder":
        path.mkdir(exist_ok=True)
    elif kind == "library-name":
        path = path.with_suffix(".imu.csv")
    elif kind == "model":
        path.write_bytes(ws.good_model)
    return path


def snapshot(folder: Path) -> dict[str, tuple[str, bytes | str]]:
    """Every entry of `folder`: a link's target, a file's bytes."""
    out: dict[str, tuple[str, bytes | str]] = {}
    for entry in folder.iterdir():
        if entry.is_symlink():
            out[entry.name] = ("link", os.readlink(entry))
        elif entry.is_file():
            out[entry.name] = ("file", entry.read_bytes())
        else:
            out[entry.name] = ("folder", "")
    return out


@fuzz(40)
@given(kind=st.sampled_from(TARGETS), name=st.text("abc.-_ ", min_size=1, max_size=8))
def test_fuzz_train_output_never_destroys_a_users_file(ws: Workspace, kind: str, name) -> None:
    target = make_target(ws, kind, name.strip(".") or "x")
    before = snapshot(target.parent)
    model_before = ws.model.read_bytes()
    outcome = run_cli("train", str(ws.library), "-o", str(target), *SMALL)
    assert_clear(outcome)
    after = snapshot(target.parent)
    if kind in ("model", "fresh") and outcome.code == 0:
        after.pop(target.name, None)
        before.pop(target.name, None)
    else:
        assert outcome.code == 2, (kind, outcome.out)
    assert after == before
    assert ws.model.read_bytes() == model_before
    assert not [p for p in target.parent.iterdir() if p.name.endswith(".tmp")]


@fuzz(30)
@given(
    kind=st.sampled_from(
        ["document", "recording", "folder", "dangling", "link-to-document", "link-to-model"]
    ),
    command=st.sampled_from(["emulate-servo", "emulate-sensors"]),
)
def test_fuzz_link_never_destroys_a_users_file(ws: Workspace, kind: str, command: str) -> None:
    target = make_target(ws, kind, "port")
    before = snapshot(target.parent)
    outcome = run_cli(command, "--link", str(target), "--seconds", "0")
    assert_clear(outcome)
    if kind == "dangling":  # a stale link: replaced, then removed on exit
        assert outcome.code == 0 and not target.is_symlink()
        before.pop(target.name)
    else:
        assert outcome.code == 2
    assert snapshot(target.parent) == before


# Names with control characters (item 2).

control_names = st.text(
    st.sampled_from(CONTROL) | st.characters(codec="utf-8", exclude_categories=["Cs"]),
    min_size=1,
    max_size=12,
)


@fuzz(200)
@given(names=st.lists(control_names, min_size=2, max_size=2, unique=True))
def test_fuzz_header_scenes_are_never_printed_raw(ws: Workspace, names: list[str]) -> None:
    def change(arrays: dict[str, np.ndarray]) -> None:
        header = json.loads(str(arrays["header"]))
        for state in header["recognisers"].values():
            renamed = dict(zip(state["scenes"], names, strict=False))
            state["scenes"] = [renamed.get(s, s) for s in state["scenes"]]
            state["cluster_scene"] = [renamed.get(s, s) for s in state["cluster_scene"]]
        arrays["header"] = np.array(json.dumps(header))

    model = mutated_model(ws, ws.model, change)
    outcome = run_cli(
        "predict", str(model), "--audio", str(ws.good_wav), "--image", str(ws.good_png)
    )
    assert_clear(outcome)
    assert not [c for c in outcome.out + outcome.err if c in CONTROL], outcome.out


# Numbers beyond floats, and finite values that overflow inside the features (items 3, 4).

extreme_numbers = st.one_of(
    st.floats(width=64),
    st.floats(width=32),
    st.floats(min_value=-1e6, max_value=1e6),
    st.sampled_from([3.4028235e38, 3.5e38, 1e307, -1e307, 1.7976931348623157e308, 0.0]),
    beyond_floats,
    st.integers(-(2**64), 2**64),
).map(lambda v: repr(v) if isinstance(v, float) else str(v))


@fuzz(800)
@given(
    kind=st.sampled_from(["imu", "ambient"]),
    rows=st.lists(st.lists(extreme_numbers, min_size=4, max_size=7), min_size=0, max_size=12),
    good=st.integers(0, 20),
)
def test_fuzz_sensor_logs_are_finite_and_in_range_or_one_line(tmp_path_factory, kind, rows, good):
    channels = CHANNELS[kind]
    ok = "0,0,9.8,0,0,0" if kind == "imu" else "300,20,1013"
    lines = [f"{i * 0.01},{ok}" for i in range(good)]
    lines += [",".join(row[: len(channels) + 1]) for row in rows]
    path = tmp_path_factory.mktemp("log") / f"log.{kind}.csv"
    path.write_text(",".join(("time", *channels)) + "\n" + "\n".join(lines) + "\n")
    try:
        log = read_sample_csv(path, kind)
    except ServantError as error:
        assert "\n" not in str(error)
        return
    assert np.isfinite(log.times).all() and np.isfinite(log.values).all()
    limits = np.array([CHANNEL_LIMITS[c] for c in channels])
    assert np.all(log.values >= limits[:, 0] - 1e-3) and np.all(log.values <= limits[:, 1] * 1.001)


@fuzz(700)
@given(kind=st.sampled_from(["I", "A"]), fields=st.lists(extreme_numbers, min_size=1, max_size=9))
def test_fuzz_board_lines_parse_in_range_or_are_refused(kind: str, fields: list[str]) -> None:
    try:
        reading = parse_line(f"{kind},{','.join(fields)}\n".encode())
    except ValueError:
        return
    assert reading is not None
    channels = CHANNELS[reading.kind]
    for channel, value in zip(channels, reading.values, strict=True):
        low, high = CHANNEL_LIMITS[channel]
        assert math.isfinite(value) and low <= value <= high


@fuzz(200)
@given(
    samples=st.lists(st.floats(width=32), min_size=1, max_size=8),
    spread=st.integers(1, 400),
)
def test_fuzz_float_samples_from_the_whole_float32_range(ws: Workspace, samples, spread) -> None:
    rng = np.random.default_rng(spread)
    signal = 0.1 * rng.standard_normal(8000).astype(np.float32)
    positions = rng.integers(0, len(signal), (len(samples), spread))
    for value, where in zip(samples, positions, strict=True):
        signal[where] = value
    path = ws.root / "extreme.wav"
    sf.write(path, signal, 8000, subtype="FLOAT")
    outcome = run_cli("predict", str(ws.model), "--audio", str(path))
    assert_clear(outcome)
    assert "nan" not in outcome.out.lower()


# Special files wherever a file is read (item 5).

SPECIAL = ["fifo", "zero", "folder", "dangling"]
READERS = {
    "model": lambda ws, p: ["predict", str(p), "--image", str(ws.good_png)],
    "recording": lambda ws, p: ["predict", str(ws.model), "--audio", str(p)],
    "picture": lambda ws, p: ["predict", str(ws.model), "--image", str(p)],
    "settings": lambda ws, p: ["servo", "move", "--settings", str(p), "--dry-run", "shoulder=5"],
    "records": lambda ws, p: ["teach", "--records", str(p)],
}


@fuzz(60)
@given(kind=st.sampled_from(SPECIAL), reader=st.sampled_from(sorted(READERS)))
def test_fuzz_special_files_are_one_line_at_once(ws: Workspace, kind: str, reader: str) -> None:
    assume(not (reader == "records" and kind == "dangling"))  # no records yet: teach asks stdin
    path = ws.root / f"special-{kind}-{reader}"
    if path.is_symlink() or path.exists():
        path.rmdir() if path.is_dir() and not path.is_symlink() else path.unlink()
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "zero":
        path.symlink_to("/dev/zero")
    elif kind == "folder":
        path.mkdir()
    else:
        path.symlink_to(ws.root / "nowhere")
    outcome = run_cli(*READERS[reader](ws, path))
    assert_clear(outcome, seconds=10)
    assert outcome.code == 2 or (kind, reader) == ("dangling", "settings")  # none: the defaults


# Labels for unknown places (issue 41 items 2 and 3).

# What broke a label before: too long, NUL, line breaks, escapes, reversing marks, lone
# surrogates, separators and dots, the unknown's own name, a file's name, another case.
NAME_PARTS = ["x" * 300, "é" * 40, "\x00", "\n", "\r", "\x1b[2J", "\u202e", "\u2028", "\ue000"]
NAME_PARTS += ["\u200d", "/", "\\", ".", "..", "<unknown>", "Cafe", "CAFE", "notes.txt", " "]
NAME_PARTS += ["\ud800", "\udfff"]
typed_names = st.one_of(
    st.text(max_size=80),
    st.sampled_from(NAME_PARTS),
    st.lists(st.sampled_from(NAME_PARTS) | st.text(max_size=6), min_size=1, max_size=5).map(
        "".join
    ),
)


def library_with_unknown(root: Path, sense: str = "audio") -> tuple[Engine, str]:
    """A library holding the place `cafe` and a file `notes.txt`, and an engine (no recogniser)
    keeping one unknown window of `sense` for a label."""
    (root / "cafe").mkdir(parents=True)
    (root / "notes.txt").write_text("mine")
    engine = Engine(library_root=root)
    rng = np.random.default_rng(1)
    if sense == "audio":
        kept = Kept("audio", rng.uniform(-0.5, 0.5, 4000).astype(np.float32), 8000)
    elif sense == "image":
        kept = Kept("image", rng.integers(0, 255, (24, 32, 3), dtype=np.uint8))
    else:
        kept = Kept("motion", rng.normal(size=(100, 6)), 50)
    return engine, engine._unknowns.keep(kept)


def tree(root: Path) -> dict[str, bytes | None]:
    """Every entry below `root`: a file's bytes, None for a folder."""
    return {
        str(p.relative_to(root)): None if p.is_dir() else p.read_bytes() for p in root.rglob("*")
    }


@fuzz(300)
@given(typed=typed_names)
def test_fuzz_a_label_is_a_place_read_back_or_one_line_writing_nothing(tmp_path_factory, typed):
    root = tmp_path_factory.mktemp("label") / "library"
    engine, window = library_with_unknown(root)
    before = tree(root)
    try:
        path = engine.label_unknown(window, typed)
    except ServantError as error:
        text = str(error)
        assert "\n" not in text and not [c for c in text if c in CONTROL], text
        assert tree(root) == before, "a refused name writes nothing"
        path = engine.label_unknown(window, "kitchen")  # and loses nothing
        assert path.parent == root / "kitchen"
        return
    place = path.parent.name
    assert path.parent.parent == root and path.is_file()
    assert place_key(place) == place_key(typed.strip())
    assert place_name(typed, root) == place, "typed again, the same place"
    library = SceneLibrary.scan(root)
    assert [r.scene for r in library.recordings if r.path == path] == [place]
    assert sorted(library.scenes) == sorted({"cafe", place})
    with pytest.raises(ServantError, match="no such unknown window"):
        engine.label_unknown(window, typed)


FAILED_WRITES = [errno.ENOSPC, errno.ENAMETOOLONG, errno.EACCES, errno.EROFS, errno.EIO]
# Where a write can fail: the place's folder made, the temporary file made or written, the
# temporary file moved into place.
STAGES = {
    "folder": (Path, "mkdir"),
    "temporary": ("servant_core.storage.tempfile.mkstemp",),
    "sync": ("servant_core.storage.os.fsync",),
    "replace": ("servant_core.storage.os.replace",),
}


@fuzz(120)
@given(
    sense=st.sampled_from(["audio", "image", "motion"]),
    code=st.sampled_from(FAILED_WRITES),
    stage=st.sampled_from(sorted(STAGES)),
    failures=st.integers(1, 3),
    place=st.sampled_from(["cafe", "kitchen"]),
)
def test_fuzz_a_label_whose_write_fails_can_be_given_again(
    tmp_path_factory, sense, code, stage, failures, place
):
    """Issue 41 item 2: the window was taken out before its write, so a full disk lost it."""
    root = tmp_path_factory.mktemp("failing") / "library"
    engine, window = library_with_unknown(root, sense)
    before = tree(root)

    def failing(*args, **kwargs):
        raise OSError(code, os.strerror(code))

    for _ in range(failures):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(*STAGES[stage], failing)
            with pytest.raises(ServantError) as failed:
                engine.label_unknown(window, place)
        assert str(failed.value).count("\n") == 0 and os.strerror(code) in str(failed.value)
        assert {k: v for k, v in tree(root).items() if v is not None} == {
            k: v for k, v in before.items() if v is not None
        }, "no file, whole or part, is left"
    path = engine.label_unknown(window, place)
    assert path.parent == root / place and path.is_file()
    assert len(tree(root)) == len(before) + 1 + (place not in before)


@fuzz(30)
@given(
    writers=st.lists(st.sampled_from(["paper", "fresh"]), min_size=2, max_size=4),
    order=st.randoms(use_true_random=False),
    existing=st.booleans(),
)
def test_fuzz_concurrent_trainings_of_one_model_file(ws: Workspace, writers, order, existing):
    """Issue 41 item 4: of trainings that all began before any of them saved, whatever order
    they finish in, the first to save wins, every later one is refused in one line, nothing it
    wrote is left, and the file always loads as the winner's model."""
    from servant_core.modelfile import load_model, replace_model
    from servant_core.storage import file_stamp

    folder = Path(tempfile.mkdtemp(prefix="concurrent-", dir=ws.root))
    target = folder / "model.npz"
    if existing:
        target.write_bytes(ws.good_model)
    models = {"paper": load_model(ws.model), "fresh": load_model(ws.fresh_model)}
    stamps = [file_stamp(target) for _ in writers]  # every run began before any saved
    finishing = list(range(len(writers)))
    order.shuffle(finishing)
    first = finishing[0]
    replace_model(target, models[writers[first]], None, stamps[first], backup=False)
    won = target.read_bytes()
    for later in finishing[1:]:
        with pytest.raises(ServantError) as refused:
            replace_model(target, models[writers[later]], None, stamps[later], backup=False)
        assert "\n" not in str(refused.value) and "someone else" in str(refused.value)
        assert target.read_bytes() == won
    assert set(load_model(target)) == set(models[writers[first]])
    assert sorted(p.name for p in folder.iterdir()) == ["model.npz"]


# Keys given twice (issue 41 item 5), through the commands that read the files.


@fuzz(80)
@given(
    records=st.booleans(),
    pick=st.integers(0, 10**6),
    new_key=st.one_of(st.none(), st.text(max_size=50)),
    value=parsed_values,
    at=st.integers(0, 100),
)
def test_fuzz_a_key_given_twice_stops_the_command_in_one_line(
    tmp_path_factory, records, pick, new_key, value, at
):
    """Any object of a valid settings file (`servant servo move --settings`) or teach-record
    file (`servant teach --records`), at any depth, holding one of its keys or any key twice:
    one `servant: error:` line naming the file and the key, before anything is asked or sent;
    the file unchanged and nothing written beside it."""
    content, key = given_twice(records, pick, new_key, value, at)
    folder = tmp_path_factory.mktemp("twice")
    path = folder / ("records.json" if records else "settings.json")
    path.write_bytes(content)
    if records:
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(sys, "stdin", io.StringIO("cafe\n10\n\n"))
            outcome = run_cli("teach", "--records", str(path), "--learner", str(folder / "l.npz"))
        assert "Scene label" not in outcome.out
    else:
        outcome = run_cli("servo", "move", "--settings", str(path), "--dry-run", "shoulder=5")
        assert "bytes" not in outcome.out
    assert_refused(outcome, str(path), "is given twice")
    shown = key if len(key) <= 40 else key[:40] + "…"
    assert repr(shown) in outcome.err, outcome.err
    assert path.read_bytes() == content
    assert [p.name for p in folder.iterdir()] == [path.name]


# Taught angles of any size (issue 41, "not covered yet"): two of 1e308 once made the learner's
# training a traceback.

angle_texts = st.one_of(
    extreme_numbers,
    st.sampled_from(["NaN", "Infinity", "-Infinity", "1e308", "-1e308", "360", "-360.0001"]),
    st.floats(-400, 400).map(repr),
)


@fuzz(120)
@given(angles=st.lists(angle_texts, min_size=1, max_size=6), places=st.integers(1, 3))
def test_fuzz_taught_angles_of_any_size_are_refused_or_reach_the_arm_within_its_limits(
    tmp_path_factory, angles, places
):
    """A teach-record file whose shoulder angles are any numbers: refused in one line naming
    the file, or learned, and every pose the learner gives a taught place is a finite angle
    that the arm's clamping brings within the shoulder's limits."""
    path = tmp_path_factory.mktemp("angles") / "records.json"
    path.write_text(records_text(angles, places))
    try:
        records = load_records(path)
    except ServantError as error:
        assert "\n" not in str(error) and str(path) in str(error)
        return
    joints = {joint.name: joint for joint in default_joints()}
    learner = ActionLearner(max_iter=20).fit(records)
    for place in learner.taught_scenes_:
        taught = learner.predict(label_scores(place, learner.scenes_), place, 100.0).pose
        assert taught is not None and all(math.isfinite(a) for a in taught.values()), taught
        pose, _ = clamp_pose(joints, taught)
        shoulder = joints["shoulder"]
        assert shoulder.min_angle <= pose["shoulder"] <= shoulder.max_angle
