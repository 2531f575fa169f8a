"""Fuzz (issue 13): settings files and teach record files, valid ones with any part replaced by any
JSON value, and text that is not JSON at all. Each is read as sound settings or records, or
refused in one clear ServantError naming the file, in bounded time; the file is never changed,
and adding a record to a file either works (the file then holds one more) or changes nothing.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servant_core.actions.learner import ActionLearner
from servant_core.actions.records import TeachRecord, append_record, label_scores, load_records
from servant_core.cli.arm import parse_pose
from servant_core.errors import ServantError
from servant_core.servo.link import ManualClock, ServoLink
from servant_core.settings import Settings, load_settings, save_settings

FUZZ = settings(
    max_examples=500,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
SECONDS = 2.0  # any one file, read or refused

# Integers a float cannot hold (issue 24 item 3): 400 digits once crashed every reader with
# `OverflowError: int too large to convert to float`.
beyond_floats = st.builds(
    lambda digits, sign: sign * 10**digits, st.integers(309, 1000), st.sampled_from([1, -1])
)
leaves = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    beyond_floats,
    st.floats(),  # NaN and Infinity too: Python's json writes and reads them
    st.text(max_size=20),
)
values = st.recursive(
    leaves,
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=10), children, max_size=4)
    ),
    max_leaves=12,
)


@st.composite
def mutated(draw: st.DrawFn, document: Any) -> Any:
    """`document` with one to three places replaced by any value, deleted, or added to."""
    document = json.loads(json.dumps(document))
    for _ in range(draw(st.integers(1, 3))):
        parent, key = document, None
        path_length = draw(st.integers(0, 4))
        for _ in range(path_length):
            if isinstance(parent, dict) and parent:
                key = draw(st.sampled_from(sorted(parent)))
            elif isinstance(parent, list) and parent:
                key = draw(st.integers(0, len(parent) - 1))
            else:
                break
            if not isinstance(parent[key], dict | list):
                break
            parent = parent[key]
        if not isinstance(parent, dict | list) or not parent:
            continue
        key = draw(
            st.sampled_from(sorted(parent) if isinstance(parent, dict) else range(len(parent)))
        )
        action = draw(st.sampled_from(["replace", "delete", "add"]))
        if action == "replace":
            parent[key] = draw(values)
        elif action == "delete":
            del parent[key]
        elif isinstance(parent, dict):
            parent[draw(st.text(max_size=10))] = draw(values)
        else:
            parent.append(draw(values))
    return document


def files(valid: Any) -> st.SearchStrategy[bytes]:
    """The bytes of a file: the valid document mutated, or not JSON at all."""
    as_json = mutated(valid).map(lambda d: json.dumps(d).encode())
    broken = st.one_of(
        st.binary(max_size=200),
        st.text(max_size=200).map(str.encode),
        st.integers(1, 200_000).map(lambda n: b"[" * n + b"]" * n),  # deep nesting
        st.integers(1, 200).map(lambda n: json.dumps(valid).encode()[:-n]),  # cut short
    )
    return st.one_of(as_json, as_json, broken)


def one_clear_line(error: ServantError, path: Path) -> None:
    text = str(error)
    assert "\n" not in text and str(path) in text


@FUZZ
@given(content=files(Settings().to_json()))
def test_any_settings_file_is_read_or_refused_in_one_line(tmp_path, content):
    path = tmp_path / "settings.json"
    path.write_bytes(content)
    started = time.monotonic()
    try:
        loaded = load_settings(path)
    except ServantError as error:
        one_clear_line(error, path)
    else:
        assert loaded.problems() == []
        again = save_settings(loaded, tmp_path / "again.json")
        assert load_settings(again) == loaded
        drive(loaded)
    assert time.monotonic() - started < SECONDS
    assert path.read_bytes() == content


def drive(loaded: Settings) -> None:
    """What the arm's commands do with settings: a dry-run link armed and moved, a typed pose."""
    clock = ManualClock()
    options = {"dry_run": True, "clock": clock, "sleep": clock.sleep}
    try:
        with ServoLink.open(None, loaded.protocol, loaded.joints, **options) as link:
            link.arm()
            first = loaded.joints[0].name
            link.move_to(parse_pose("45", first))
            link.move_to({j.name: j.home_angle for j in loaded.joints})
            loaded.joint(first)
            unknown = "".join(j.name for j in loaded.joints) + "?"
            with pytest.raises(ServantError, match="no joint named"):
                link.move_to({unknown: 1.0})  # the message lists the joints there are
    except ServantError as error:  # e.g. a joint the protocol cannot drive: said in one line
        assert "\n" not in str(error)


def valid_records() -> dict[str, Any]:
    records = [
        TeachRecord("coffee", label_scores("coffee"), {"shoulder": 42.0}, 1.0),
        TeachRecord(
            "gym",
            {"acoustic": {"gym": 0.7, "coffee": 0.3}, "visual": {"gym": 0.9}},
            {"shoulder": 10.0, "elbow": 30.0},
            2.0,
            "perceived",
            ["shoulder: 100 is beyond 0..90 degrees, clamped to 90"],
        ),
    ]
    return json.loads(
        json.dumps(
            {
                "format": "servant-teach-records",
                "version": 2,
                "records": [{**r.__dict__} for r in records],
            }
        )
    )


NEW = TeachRecord("street", label_scores("street"), {"elbow": 70.0}, 3.0)


@FUZZ
@given(content=files(valid_records()))
def test_any_teach_record_file_is_read_or_refused_in_one_line(tmp_path, content):
    path = tmp_path / "records.json"
    path.write_bytes(content)
    started = time.monotonic()
    try:
        records = load_records(path)
    except ServantError as error:
        one_clear_line(error, path)
        records = None
    if records is not None:
        for record in records:
            numbers = [
                *record.pose.values(),
                *(v for s in record.scores.values() for v in s.values()),
            ]
            assert record.scene and all(math.isfinite(n) for n in numbers)
        home = {"shoulder": 0.0, "elbow": 90.0, "gripper": 0.0}
        try:
            ActionLearner(max_iter=2, home=home).fit([*records, NEW])
        except ServantError as error:  # a joint no record nor home sets: said, not a crash
            assert "\n" not in str(error)
    try:
        after = append_record(NEW, path)
    except ServantError as error:
        one_clear_line(error, path)
        assert records is None
        assert path.read_bytes() == content
    else:
        assert records is not None and after == [*records, NEW]
        assert load_records(path) == after
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert time.monotonic() - started < SECONDS


def number_paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    """The place of every number in a JSON document."""
    if isinstance(node, dict):
        return [p for key, value in node.items() for p in number_paths(value, (*prefix, key))]
    if isinstance(node, list):
        return [p for i, value in enumerate(node) for p in number_paths(value, (*prefix, i))]
    return [prefix] if isinstance(node, int | float) and not isinstance(node, bool) else []


def with_number(document: Any, path: tuple, value: int) -> bytes:
    document = json.loads(json.dumps(document))
    node = document
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return json.dumps(document).encode()


@FUZZ
@given(pick=st.integers(0, 10**6), value=beyond_floats, records=st.booleans())
def test_any_number_beyond_floats_is_refused_in_one_line(tmp_path, pick, value, records):
    """Issue 24 item 3: each number of a settings or teach record file replaced by an integer
    of 309 to 1000 digits; the file is refused in one line (never an OverflowError)."""
    document = valid_records() if records else Settings().to_json()
    paths = number_paths(document)
    content = with_number(document, paths[pick % len(paths)], value)
    path = tmp_path / "file.json"
    path.write_bytes(content)
    with pytest.raises(ServantError) as refused:
        load_records(path) if records else load_settings(path)
    one_clear_line(refused.value, path)
    assert "too large" in str(refused.value)


# Any JSON value the reader parses (no number beyond floats, refused first for itself).
parsed_values = st.recursive(
    st.one_of(
        st.none(), st.booleans(), st.integers(-(2**70), 2**70), st.floats(), st.text(max_size=20)
    ),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=10), children, max_size=4)
    ),
    max_leaves=12,
)


def objects_in(node: Any, prefix: tuple = ()) -> list[tuple]:
    """The place of every object (dict) in a JSON document, the document itself first."""
    if isinstance(node, list):
        return [p for i, value in enumerate(node) for p in objects_in(value, (*prefix, i))]
    if not isinstance(node, dict):
        return []
    return [prefix, *(p for key, value in node.items() for p in objects_in(value, (*prefix, key)))]


def encoded(node: Any, twice: tuple, key: str, value: Any, at: int, prefix: tuple = ()) -> str:
    """`node` as JSON text, the object at `twice` holding `key` a second time (with `value`),
    inserted as its `at`-th member: text `json.dumps` cannot write."""
    if isinstance(node, list):
        inner = (encoded(v, twice, key, value, at, (*prefix, i)) for i, v in enumerate(node))
        return "[" + ", ".join(inner) + "]"
    if not isinstance(node, dict):
        return json.dumps(node)
    members = [
        f"{json.dumps(k)}: {encoded(v, twice, key, value, at, (*prefix, k))}"
        for k, v in node.items()
    ]
    if prefix == twice:
        members.insert(at % (len(members) + 1), f"{json.dumps(key)}: {json.dumps(value)}")
    return "{" + ", ".join(members) + "}"


def given_twice(records: bool, pick: int, new_key: str | None, value: object, at: int):
    """(the bytes of a valid settings or teach-record file with one key given twice in one of
    its objects, that key): one of the object's own keys again, or `new_key` written twice."""
    document = valid_records() if records else Settings().to_json()
    where = objects_in(document)
    twice = where[pick % len(where)]
    target = document
    for step in twice:
        target = target[step]
    own = sorted(target)
    key = own[pick % len(own)] if new_key is None and own else (new_key or "")
    if key not in target:
        target[key] = value  # written once here, and once more by `encoded`
    return encoded(document, twice, key, value, at).encode(), key


@FUZZ
@given(
    records=st.booleans(),
    pick=st.integers(0, 10**6),
    new_key=st.one_of(st.none(), st.text(max_size=60)),
    value=parsed_values,
    at=st.integers(0, 100),
)
def test_any_key_given_twice_is_refused_naming_it(tmp_path, records, pick, new_key, value, at):
    """Issue 41 item 5: Python's json keeps the last of two equal keys, so a shoulder's second
    `max_angle` silently won. Any object of a settings or teach record file holding a key twice
    (one of its own keys again, or any key written twice) is refused in one line naming the key,
    and the file is left as it was."""
    content, key = given_twice(records, pick, new_key, value, at)
    path = tmp_path / "file.json"
    path.write_bytes(content)
    with pytest.raises(ServantError) as refused:
        load_records(path) if records else load_settings(path)
    one_clear_line(refused.value, path)
    shown = key if len(key) <= 40 else key[:40] + "…"
    assert f"the key {shown!r} is given twice" in str(refused.value)
    assert path.read_bytes() == content
