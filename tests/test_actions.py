"""Teach records on disk and the action learner."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError
from sklearn.neural_network import MLPRegressor

from servant_core.actions.learner import ActionLearner, forward
from servant_core.actions.records import (
    TeachRecord,
    append_record,
    default_records_path,
    label_scores,
    load_records,
)
from servant_core.errors import ServantError

SCENES = ["coffee", "gym", "street"]


def record(scene, pose, scenes=SCENES, t=0.0):
    return TeachRecord(scene, label_scores(scene, scenes), pose, t)


def perceived(scene, strength):
    """Scores as recognisers give them: most mass on `scene`, the rest spread."""
    rest = (1 - strength) / (len(SCENES) - 1)
    scores = {s: strength if s == scene else rest for s in SCENES}
    return {"acoustic": scores, "visual": dict(scores)}


@pytest.fixture(scope="module")
def learner():
    records = [record("coffee", {"shoulder": 42.0}), record("gym", {"shoulder": 10.0})]
    return ActionLearner(max_iter=2000).fit(records)


def test_records_round_trip_atomically():
    first = record("coffee", {"shoulder": 42.0}, t=1.0)
    second = TeachRecord(
        "gym", perceived("gym", 0.7), {"shoulder": 10.0, "elbow": 30.0}, 2.0, "perceived"
    )
    append_record(first)
    assert append_record(second) == [first, second]
    assert load_records() == [first, second]
    assert not list(default_records_path().parent.glob("*.tmp"))


def test_appends_see_what_another_writer_put_in_the_file_meanwhile(tmp_path):
    """Appends reuse the records this process last read or wrote while the file is unchanged
    (3,000 labels on `servant teach` re-read the whole file each time); a file another writer
    replaced, or changed in place, is read again, and nothing of theirs is lost."""
    path = tmp_path / "records.json"
    append_record(record("coffee", {"shoulder": 40.0}), path)
    append_record(record("gym", {"shoulder": 10.0}), path)
    # another process (the app beside `servant teach`) adds a record: a new file put in place
    data = json.loads(path.read_text())
    data["records"].append(json.loads(json.dumps(data["records"][0])) | {"scene": "street"})
    other = tmp_path / "other.json"
    other.write_text(json.dumps(data))
    other.replace(path)
    after = append_record(record("office", {"shoulder": 5.0}), path)
    assert [r.scene for r in after] == ["coffee", "gym", "street", "office"]
    # an editor that writes in place (same inode): a different length is seen too
    data = json.loads(path.read_text())
    data["records"] = data["records"][:1]
    with path.open("r+") as handle:
        handle.seek(0)
        handle.truncate()
        handle.write(json.dumps(data))
    assert [r.scene for r in load_records(path)] == ["coffee"]
    after = append_record(record("gym", {"shoulder": 11.0}), path)
    assert [r.scene for r in after] == ["coffee", "gym"]
    assert [r.scene for r in load_records(path)] == ["coffee", "gym"]


def test_a_broken_record_file_is_refused_and_kept(tmp_path):
    path = tmp_path / "records.json"
    path.write_text('{"format": "servant-teach-records", "version": 2, "records": [')
    before = path.read_bytes()
    with pytest.raises(ServantError, match="not a readable teach record file"):
        append_record(record("coffee", {"shoulder": 1.0}), path)
    assert path.read_bytes() == before


def test_a_bad_record_is_named(tmp_path):
    path = tmp_path / "records.json"
    good = {"scene": "gym", "scores": {"acoustic": {"gym": 1.0}}, "pose": {"shoulder": 3}}
    bad = {"scene": "coffee", "scores": {"acoustic": {"coffee": 1.0}}, "pose": {"shoulder": "high"}}
    path.write_text(
        json.dumps({"format": "servant-teach-records", "version": 2, "records": [good, bad]})
    )
    with pytest.raises(ServantError, match=r"record 2: pose\['shoulder'\] is not a finite number"):
        load_records(path)


@pytest.mark.parametrize(
    ("records", "message"),
    [
        # Issue 13, 8: a deeply nested file ended in a RecursionError.
        ("[" * 100_000 + "]" * 100_000, r"not a readable teach record file \(nested too deeply\)"),
        ([{"scene": "a", "scores": {"acoustic": {"a": 1}}, "pose": {"x": 1}, "t": True}], "t is"),
        (
            [{"scene": "a", "scores": {"visual": {"a": 1}}, "pose": {"x": 1}, "notes": [[]]}],
            "notes",
        ),
    ],
)
def test_malformed_records_are_one_clear_line_and_kept(tmp_path, records, message):
    path = tmp_path / "records.json"
    if isinstance(records, str):
        text = f'{{"format": "servant-teach-records", "version": 2, "records": {records}}}'
    else:
        text = json.dumps({"format": "servant-teach-records", "version": 2, "records": records})
    path.write_text(text)
    with pytest.raises(ServantError, match=message):
        append_record(record("coffee", {"shoulder": 1.0}), path)
    assert path.read_text() == text


def test_records_from_an_older_version_are_migrated_and_backed_up(tmp_path):
    path = tmp_path / "records.json"
    v1 = {
        "format": "servant-teach-records",
        "version": 1,
        "records": [{"scene": "coffee", "action": 42, "t": 5}, {"scene": "gym", "action": 10}],
    }
    path.write_text(json.dumps(v1))
    records = load_records(path, legacy_joint="elbow")
    assert [(r.scene, r.pose) for r in records] == [
        ("coffee", {"elbow": 42.0}),
        ("gym", {"elbow": 10.0}),
    ]
    assert records[0].scores["visual"] == {"coffee": 1.0}
    append_record(record("street", {"elbow": 70.0}), path, legacy_joint="elbow")
    assert json.loads((tmp_path / "records.json.v1.bak").read_text()) == v1
    assert [r.scene for r in load_records(path)] == ["coffee", "gym", "street"]


def test_records_from_a_newer_version_are_refused(tmp_path):
    path = tmp_path / "records.json"
    path.write_text(json.dumps({"format": "servant-teach-records", "version": 3, "records": []}))
    with pytest.raises(ServantError, match="version 3 is not one this Servant reads"):
        load_records(path)


def test_learner_reproduces_fig6_and_reports_a_falling_error():
    reports = []
    records = [record("coffee", {"shoulder": 42.0}), record("gym", {"shoulder": 10.0})]
    learner = ActionLearner(max_iter=3000, report_every=1000).fit(
        records, report=lambda *r: reports.append(r)
    )
    assert [i for i, _ in reports] == [1, 1000, 2000, 3000]
    assert reports[-1][1] < reports[0][1] / 100
    assert learner.predict(label_scores("coffee", SCENES), "coffee", 100).pose[
        "shoulder"
    ] == pytest.approx(42, abs=0.5)
    assert learner.predict(label_scores("gym", SCENES), "gym", 100).pose[
        "shoulder"
    ] == pytest.approx(10, abs=0.5)


def test_learner_refuses_untaught_scenes_and_low_confidence(learner):
    scores = label_scores("street", SCENES)
    refused = learner.predict(scores, "street", 100)
    assert not refused.acted and "never taught" in refused.reason
    low = learner.predict(label_scores("coffee", SCENES), "coffee", 49.9)
    assert not low.acted and "under the threshold of 50%" in low.reason
    assert not learner.predict(scores, None, 100).acted
    with pytest.raises(NotFittedError):
        ActionLearner().predict(scores, "coffee", 100)


def test_pose_for_is_a_pose_or_a_reason(learner):
    assert learner.pose_for("gym") == pytest.approx({"shoulder": 10.0}, abs=0.5)
    with pytest.raises(ServantError, match="arm: I was never taught what to do in 'street'"):
        learner.pose_for("street")
    with pytest.raises(ServantError, match="under the threshold"):
        learner.pose_for("coffee", confidence=10.0)


def test_learner_uses_the_perceived_scores():
    records = [
        TeachRecord("coffee", perceived("coffee", 0.9), {"shoulder": 60.0}, 0, "perceived"),
        TeachRecord("gym", perceived("gym", 0.9), {"shoulder": 0.0}, 0, "perceived"),
    ]
    learner = ActionLearner(max_iter=2000).fit(records)
    sure = learner.pose(perceived("coffee", 0.9))["shoulder"]
    unsure = learner.pose(perceived("coffee", 0.5))["shoulder"]
    assert sure == pytest.approx(60, abs=1)
    assert unsure < sure  # less coffee-like scores, a pose further from coffee's


def test_missing_joints_take_home_or_are_refused():
    records = [
        record("coffee", {"shoulder": 42.0, "elbow": 20.0}),
        record("gym", {"shoulder": 10.0}),
    ]
    with pytest.raises(ServantError, match=r"record 2 \(gym\) has no angle for joint 'elbow'"):
        ActionLearner(max_iter=10).fit(records)
    learner = ActionLearner(max_iter=2000, home={"elbow": 90.0}).fit(records)
    assert learner.pose(label_scores("gym", SCENES)) == pytest.approx(
        {"shoulder": 10.0, "elbow": 90.0}, abs=0.5
    )


def test_learner_file_round_trip_without_pickle(learner, tmp_path):
    path = learner.save(tmp_path / "learner.npz")
    with np.load(path, allow_pickle=False) as npz:
        assert "coef_0" in npz.files
    loaded = ActionLearner.load(path)
    for scene in ("coffee", "gym"):
        assert loaded.pose(label_scores(scene, SCENES)) == learner.pose(label_scores(scene, SCENES))
    assert loaded.history_ == learner.history_
    assert loaded.predict(label_scores("street", SCENES), "street", 100).reason


def test_damaged_learner_files_are_refused(tmp_path):
    with pytest.raises(ServantError, match="no trained action learner"):
        ActionLearner.load(tmp_path / "none.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(ServantError, match="not a Servant action learner"):
        ActionLearner.load(junk)


@pytest.mark.filterwarnings("ignore::sklearn.exceptions.ConvergenceWarning")
def test_numpy_forward_pass_matches_scikit_learn():
    rng = np.random.default_rng(0)
    x, y = rng.random((20, 6)), rng.random((20, 2))
    for activation in ("tanh", "relu", "logistic"):
        net = MLPRegressor(
            hidden_layer_sizes=(8, 5), activation=activation, max_iter=50, random_state=0
        ).fit(x, y)
        assert np.allclose(forward(x, net.coefs_, net.intercepts_, activation), net.predict(x))
