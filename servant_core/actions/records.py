"""Teach records: what the engine perceived (every scene's score, per sense) and the pose taught.

They live in one JSON file (default `data_dir()/teach/records.json`), rewritten atomically on each
new record. A file from an older version is read and migrated (its original is kept beside it as
`.v<N>.bak` before the first rewrite); a broken or newer file is refused and never overwritten.
Version 1 is the paper's shape: a scene label and one servo angle (`{"scene", "action", "t"}`);
it becomes a pose for one joint (`legacy_joint`) and certain scores for its scene.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from servant_core.errors import ServantError
from servant_core.json_objects import unique_keys
from servant_core.numbers import is_finite_number, json_loads
from servant_core.settings import MAX_ABS_ANGLE
from servant_core.storage import (
    atomic_write_bytes,
    check_replaceable,
    data_dir,
    no_file_yet,
    os_reason,
    read_bounded_bytes,
)

FORMAT = "servant-teach-records"
VERSION = 2
SENSES = ("acoustic", "visual")
SOURCES = ("typed", "recorded", "perceived")
MAX_FILE_BYTES = 64 << 20  # some 300,000 records: far more than anyone teaches
# The action learner reads two scores a scene for each record: 20,000 scenes once asked for
# 3.5 GB. A wearer teaches dozens of places and some hundreds of records; these bound the
# learner's table to some 160 MB.
MAX_SCENES = 500
MAX_RECORDS = 20_000


@dataclass(frozen=True)
class TeachRecord:
    scene: str
    scores: dict[str, dict[str, float]]  # {"acoustic": {scene: score}, "visual": {scene: score}}
    pose: dict[str, float]  # degrees per joint
    t: float  # when it was taught, seconds since the epoch
    source: str = "typed"  # typed by the user, recorded by guiding the arm, or perceived live
    notes: list[str] = field(default_factory=list)


def one_hot(scene: str, scenes: Iterable[str] = ()) -> dict[str, float]:
    return {s: float(s == scene) for s in sorted({*scenes, scene})}


def label_scores(scene: str, scenes: Iterable[str] = ()) -> dict[str, dict[str, float]]:
    """Scores for a scene the user typed (not perceived): certain, for both senses.

    `scenes` only adds explicit zeros: a scene without a score counts as 0 (see
    `ActionLearner.features`). Records stored one after another leave it out, so that each one
    does not grow with the number of scenes taught before it (quadratic growth, issue 13).
    """
    scores = one_hot(scene, scenes)
    return {sense: dict(scores) for sense in SENSES}


def default_records_path() -> Path:
    return data_dir() / "teach" / "records.json"


def _finite_map(value: Any, what: str) -> dict[str, float]:
    if not isinstance(value, Mapping) or not value:
        raise ValueError(f"{what} must be a non-empty object of numbers")
    if len(value) > MAX_SCENES:
        raise ValueError(f"{what} has more than {MAX_SCENES} entries")
    out = {}
    for key, number in value.items():
        if not is_finite_number(number):
            raise ValueError(f"{what}[{key!r}] is not a finite number")
        out[str(key)] = float(number)
    return out


def _pose(value: Any) -> dict[str, float]:
    """A record's pose: an angle a joint can take for each joint named. A pose is clamped to
    its joints' limits when it is taught, and no joint's limits go beyond `MAX_ABS_ANGLE`: an
    angle past them was written by hand (two of 1e308 made the learner's mean infinite, and its
    training a traceback)."""
    pose = _finite_map(value, "pose")
    for joint, angle in pose.items():
        if abs(angle) > MAX_ABS_ANGLE:
            raise ValueError(
                f"pose[{joint!r}] is {angle:g} degrees, beyond any joint's "
                f"{-MAX_ABS_ANGLE:g}..{MAX_ABS_ANGLE:g}"
            )
    return pose


def _record(raw: Any) -> TeachRecord:
    if not isinstance(raw, Mapping):
        raise ValueError("not an object")
    scene = raw.get("scene")
    if not isinstance(scene, str) or not scene:
        raise ValueError("no scene label")
    scores = raw.get("scores")
    if not isinstance(scores, Mapping) or not set(scores) <= set(SENSES) or not scores:
        raise ValueError(f"scores must be an object with {' and/or '.join(SENSES)}")
    source = raw.get("source", "typed")
    if source not in SOURCES:
        raise ValueError(f"source {source!r} is unknown")
    t = raw.get("t", 0.0)
    if not is_finite_number(t):
        raise ValueError("t is not a time")
    notes = raw.get("notes", [])
    if not isinstance(notes, list) or not all(isinstance(n, str) for n in notes):
        raise ValueError("notes must be a list of texts")
    return TeachRecord(
        scene=scene,
        scores={s: _finite_map(v, f"scores[{s!r}]") for s, v in scores.items()},
        pose=_pose(raw.get("pose")),
        t=float(t),
        source=source,
        notes=list(notes),
    )


def _migrate_v1(raw_records: Sequence[Any], legacy_joint: str) -> list[dict[str, Any]]:
    return [
        {
            "scene": r.get("scene"),
            "scores": label_scores(r["scene"]) if isinstance(r.get("scene"), str) else None,
            "pose": {legacy_joint: r.get("action")},
            "t": r.get("t", 0.0),
        }
        if isinstance(r, Mapping)
        else r
        for r in raw_records
    ]


@dataclass
class _Known:
    """A record file as this process last read or wrote it: what identifies that version of
    the file (inode, modification time, size), its records and their lines."""

    signature: tuple[int, int, int]
    records: list[TeachRecord]
    lines: list[str] | None = None


# Record files this process has read or written, by absolute path. `servant teach` adds a record
# a label, and reading and checking every record each time made 3,000 labels take minutes
# (issue 24); an unchanged file is taken from here instead. Another writer (the app and the CLI
# at once) replaces the file, which changes its inode: it is then read again.
_KNOWN: dict[Path, _Known] = {}


def _signature(path: Path) -> tuple[int, int, int] | None:
    try:
        status = os.stat(path)
    except OSError:
        return None
    return (status.st_ino, status.st_mtime_ns, status.st_size)


def _remember(
    path: Path,
    signature: tuple[int, int, int] | None,
    records: Sequence[TeachRecord],
    lines: list[str] | None,
) -> None:
    """Keep what `path` held when it had `signature`, unless it has changed since (another
    writer, between this process's read or write and now): then it is read again next time."""
    if signature is not None and signature == _signature(path):
        _KNOWN[path.absolute()] = _Known(signature, list(records), lines)
    else:
        _KNOWN.pop(path.absolute(), None)


def _load(path: Path, legacy_joint: str) -> tuple[int, list[TeachRecord], list[str] | None]:
    """(version, records, their lines if known) of the file, from `_KNOWN` while unchanged."""
    known = _KNOWN.get(path.absolute())
    if known is not None and known.signature == _signature(path):
        lines = None if known.lines is None else list(known.lines)
        return VERSION, list(known.records), lines
    before = _signature(path)
    version, records = _read(path, legacy_joint)
    if version == VERSION:
        _remember(path, before, records, None)
    return version, records, None


def _read(path: Path, legacy_joint: str) -> tuple[int, list[TeachRecord]]:
    fix = "fix or move the file away (Servant never overwrites it)"
    text = read_bounded_bytes(path, "teach record file", MAX_FILE_BYTES)
    try:
        data = json_loads(text.decode("utf-8"), object_pairs_hook=unique_keys)
    except RecursionError as exc:
        raise ServantError(
            f"{path}: not a readable teach record file (nested too deeply); {fix}"
        ) from exc
    except (UnicodeDecodeError, ValueError) as exc:
        raise ServantError(f"{path}: not a readable teach record file ({exc}); {fix}") from exc
    if not isinstance(data, Mapping) or data.get("format") != FORMAT:
        raise ServantError(f"{path}: not a Servant teach record file; {fix}")
    version = data.get("version")
    if not isinstance(version, int) or not 1 <= version <= VERSION:
        raise ServantError(
            f"{path}: teach record version {version!r} is not one this Servant reads "
            f"(1..{VERSION}); "
            "upgrade Servant"
        )
    raw_records = data.get("records")
    if not isinstance(raw_records, list):
        raise ServantError(f"{path}: no list of records; {fix}")
    if version == 1:
        raw_records = _migrate_v1(raw_records, legacy_joint)
    if len(raw_records) > MAX_RECORDS:
        raise ServantError(f"{path}: more than {MAX_RECORDS:,} records; {fix}")
    records = []
    for i, raw in enumerate(raw_records):
        try:
            records.append(_record(raw))
        except ValueError as exc:
            raise ServantError(f"{path}: record {i + 1}: {exc}; {fix}") from exc
    _check_bounds(path, records, fix)
    return version, records


def _check_bounds(path: Path, records: Sequence[TeachRecord], fix: str) -> None:
    """At most `MAX_RECORDS` records over at most `MAX_SCENES` scenes (labels and scored)."""
    if len(records) > MAX_RECORDS:
        raise ServantError(f"{path}: more than {MAX_RECORDS:,} records; {fix}")
    scenes = {r.scene for r in records}
    for record in records:
        for scores in record.scores.values():
            scenes.update(scores)
        if len(scenes) > MAX_SCENES:
            raise ServantError(f"{path}: records name more than {MAX_SCENES} scenes; {fix}")


def load_records(
    path: str | Path | None = None, legacy_joint: str = "shoulder"
) -> list[TeachRecord]:
    """Every record in `path` (default `default_records_path()`); none if there is no file."""
    path = Path(path) if path is not None else default_records_path()
    if no_file_yet(path, "teach record file", "fix the link or remove it"):
        return []
    return _load(path, legacy_joint)[1]


def _fields(record: TeachRecord) -> dict[str, Any]:
    """The record as JSON would have it (a shallow view: `asdict` deep-copies, far slower)."""
    return {f.name: getattr(record, f.name) for f in fields(TeachRecord)}


def _line(record: TeachRecord) -> str:
    return json.dumps(_fields(record), sort_keys=True)


def _text(lines: Sequence[str]) -> str:
    head = json.dumps({"format": FORMAT, "version": VERSION})[:-1]
    body = ",\n".join(lines)
    return f'{head}, "records": [\n{body}\n]}}\n' if lines else f'{head}, "records": []}}\n'


def encode_records(records: Sequence[TeachRecord]) -> str:
    """The file's text: one record a line, so that it stays readable and diffable."""
    return _text([_line(r) for r in records])


def check_records_output(path: str | Path | None = None) -> Path:
    """`path` if teach records may be written there: not a symbolic link (replacing it loses the
    link), nor a read-only file, nor a name a scene library reads. What the file holds is
    checked where it is read: an append reads it first, and refuses a file of other things."""
    path = Path(path) if path is not None else default_records_path()
    check_replaceable(path, "teach record file", lambda _: True)
    return path


def save_records(
    records: Sequence[TeachRecord], path: str | Path | None = None, lines: list[str] | None = None
) -> Path:
    """Write the records (`lines`: their lines, if made already), atomically."""
    path = check_records_output(path)
    lines = lines if lines is not None else [_line(r) for r in records]
    data = _text(lines).encode("utf-8")
    try:
        written = atomic_write_bytes(path, data)
    except OSError as exc:
        raise ServantError(
            f"{path}: cannot save the teach records ({os_reason(exc)}); the file is unchanged; "
            "check that its folder can be written to and has space"
        ) from None
    signature = _signature(path)
    if signature is not None and signature[2] != len(data):  # another writer's file by now
        signature = None
    _remember(path, signature, records, lines)
    return written


def append_record(
    record: TeachRecord, path: str | Path | None = None, legacy_joint: str = "shoulder"
) -> list[TeachRecord]:
    """Add `record` to the file, atomically; returns every record now in it."""
    path = Path(path) if path is not None else default_records_path()
    try:  # the same checks a reader applies: never write what cannot be read
        _record(_fields(record))
    except ValueError as exc:
        raise ServantError(
            f"{path}: the teach record for {record.scene!r} was not added ({exc}); the file "
            "is unchanged: correct that and add it again"
        ) from None
    version, records, lines = _load(path, legacy_joint) if path.exists() else (VERSION, [], [])
    if version < VERSION:
        backup = path.with_name(f"{path.name}.v{version}.bak")
        if not backup.exists():
            try:
                atomic_write_bytes(backup, path.read_bytes())
            except OSError as exc:
                raise ServantError(
                    f"{backup}: cannot keep the old teach records ({os_reason(exc)}); nothing "
                    "was changed; check that the folder can be written to and has space"
                ) from None
    records.append(record)
    _check_bounds(path, records, "nothing was added; start another record file")
    lines = [*lines, _line(record)] if lines is not None else None
    save_records(records, path, lines)
    return records
