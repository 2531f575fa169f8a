"""Which windows and pictures train and which test: the splits and each protocol's folds.

Audio protocols: `temporal` — the first 60 % of each recording's windows train, the rest test;
`recording` — leave one recording out; `source` — leave one group of recordings out (by default
a file's source, its name up to the first `-`); `fewshot` — the first k windows of each
recording train, the temporal test part tests; `taught` — what suits a library taught in the app.
Pictures: the first part of each scene's files by name train (`file_order_split`).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servant_core.choices import DEFAULT_SHOTS, EVAL_PROTOCOLS, IMAGE_TRAIN_FRACTION
from servant_core.errors import ServantError
from servant_core.library import Picture, SceneLibrary, WindowFeatures
from servant_core.storage import read_bounded_bytes

PROTOCOLS = EVAL_PROTOCOLS
# For a library taught in the app, 5 s at a time: `temporal` where recordings are long enough to
# split, else `recording` (leave one out: each recording is one sample). The result names which.
TAUGHT = "taught"
TRAIN_FRACTION = 0.6
# A line a recording: a thousand times the largest library Servant was evaluated on.
MAX_GROUPS_BYTES = 16 << 20


def temporal_split(
    recording: np.ndarray, position: np.ndarray, fraction: float = TRAIN_FRACTION
) -> np.ndarray:
    """Boolean train mask: the first `fraction` of each recording's windows (at least one of
    each side when the recording has two windows or more)."""
    train = np.zeros(len(position), dtype=bool)
    for r in np.unique(recording):
        rows = recording == r
        n = int(rows.sum())
        n_train = min(max(int(math.floor(fraction * n)), 1), max(n - 1, 1))
        train[rows] = position[rows] < n_train
    return train


def file_order_split(
    pictures: Sequence[Picture], fraction: float = IMAGE_TRAIN_FRACTION
) -> np.ndarray:
    """Boolean train mask over pictures: the first `fraction` of each scene's files by name."""
    train = np.zeros(len(pictures), dtype=bool)
    by_scene: dict[str, list[int]] = {}
    for i, picture in enumerate(pictures):
        by_scene.setdefault(picture.scene, []).append(i)
    for indices in by_scene.values():
        indices.sort(key=lambda i: pictures[i].path.name)
        n_train = min(max(int(math.floor(fraction * len(indices))), 1), max(len(indices) - 1, 1))
        train[indices[:n_train]] = True
    return train


def fewshot_split(
    recording: np.ndarray, position: np.ndarray, shots: int, fraction: float = TRAIN_FRACTION
) -> np.ndarray:
    """Boolean train mask of teach mode's reality: the first `shots` windows of each recording,
    never beyond its temporal train part (so the temporal test part stays unseen)."""
    return temporal_split(recording, position, fraction) & (position < shots)


def source_of(path: Path) -> str:
    """A recording's source: its file name up to the first `-` (`moodist-cafe.mp3`: `moodist`;
    a name without one is a source of its own)."""
    return Path(path).stem.split("-", 1)[0]


def read_groups(path: Path, root: Path) -> dict[str, str]:
    """A `--groups` file: one recording a line, its path (relative to `root`, or absolute below
    it) and then its group, the line's last word; blank lines and `#` comments are skipped.
    Returns recording path relative to `root` (POSIX) -> group."""
    data = read_bounded_bytes(path, "groups file", MAX_GROUPS_BYTES)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise ServantError(f"{path}: cannot read the groups file ({error})") from None
    groups: dict[str, str] = {}
    for number, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        parts = line.rsplit(None, 1)
        if len(parts) != 2:
            raise ServantError(
                f"{path}:{number}: expected a recording's path and then its group, found {line!r}"
            )
        name, group = Path(parts[0]), parts[1]
        if name.is_absolute():
            try:
                name = name.relative_to(root)
            except ValueError:
                raise ServantError(
                    f"{path}:{number}: {name} is not below the scene library {root}"
                ) from None
        groups[name.as_posix()] = group
    return groups


def recording_groups(library: SceneLibrary, groups: Mapping[str, str] | None = None) -> list[str]:
    """The group of each of `library`'s recordings (in its order): from `groups` (recording path
    relative to the library's root -> group), or its source (`source_of`) without one. A
    recording `groups` does not name is an error: guessing its group could leak it into a fold
    that tests its twin."""
    if groups is None:
        return [source_of(r.path) for r in library.recordings]
    names = [r.path.relative_to(library.root).as_posix() for r in library.recordings]
    missing = [name for name in names if name not in groups]
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise ServantError(
            f"the groups file names no group for {', '.join(missing[:3])}{more}; give every "
            "recording of the library a line `PATH GROUP`"
        )
    return [groups[name] for name in names]


@dataclass
class AudioPlan:
    """One scored row: a model per fold fitted on `folds[i]` (train mask over the windows) and
    tested on `tests[i]`; `shots` for a fewshot row; `left_out[i]` names the group fold i
    holds out (source protocol)."""

    protocol: str
    folds: list[np.ndarray]
    tests: list[np.ndarray]
    shots: int | None = None
    left_out: list[str] | None = None


def audio_plans(
    wf: WindowFeatures,
    protocol: str,
    shots: Sequence[int] = DEFAULT_SHOTS,
    groups: Sequence[str] | None = None,
) -> list[AudioPlan]:
    """The folds of `protocol` over `wf`'s windows: `temporal` one fold, `recording` one per
    recording (tested on it alone), `source` one per group of recordings (`groups[i]` is the
    group of `wf.recordings[i]`; default: each recording's source), `fewshot` one row per number
    of shots (each tested on the temporal test part)."""
    temporal = temporal_split(wf.recording, wf.position)
    if protocol == TAUGHT:
        protocol = _taught_protocol(wf, temporal)
    if protocol == "temporal":
        return [AudioPlan(protocol, [temporal], [~temporal])]
    if protocol == "fewshot":
        return [
            AudioPlan(protocol, [fewshot_split(wf.recording, wf.position, k)], [~temporal], k)
            for k in shots
        ]
    if protocol == "source":
        if groups is None:
            groups = [source_of(r.path) for r in wf.recordings]
        if len(groups) != len(wf.recordings):
            raise ValueError("one group per recording of the windows is needed")
        window_group = np.array(groups, dtype=object)[wf.recording]
        left_out = sorted(set(window_group.tolist()))
        tests = [window_group == g for g in left_out]
        return [AudioPlan(protocol, [~t for t in tests], tests, left_out=left_out)]
    rows = [wf.recording != r for r in np.unique(wf.recording)]
    return [AudioPlan(protocol, rows, [~row for row in rows])]


def _taught_protocol(wf: WindowFeatures, temporal: np.ndarray) -> str:
    """What `taught` means for a library: leave one recording out once teach mode's 5 s samples
    (one window each) are in it, so that every sample is tested, not the later part of a longer
    recording alone; `temporal` for a library of longer recordings only."""
    samples = np.bincount(wf.recording, minlength=len(wf.recordings)) == 1
    why_not = _samples_to_leave_out(wf)
    if why_not is None and samples.any():
        return "recording"
    if (~temporal).any():
        return "temporal"
    if why_not is not None:
        raise ServantError(why_not)
    return "recording"


def _samples_to_leave_out(wf: WindowFeatures) -> str | None:
    """Why one sample cannot be left out at a time (teach mode's words), or None: it needs two
    places, each with two samples or more (a place whose only sample is left out cannot be
    recognised)."""
    per_scene = Counter(str(wf.scenes[wf.recording == r][0]) for r in np.unique(wf.recording))
    if len(per_scene) < 2:
        return (
            "nothing to evaluate yet: teach a second place in teach mode (key t), with two "
            "recordings or more"
        )
    single = sorted(scene for scene, n in per_scene.items() if n < 2)
    if single:
        return (
            f"nothing to evaluate yet: record another sample of {', '.join(single)} in teach "
            "mode (key t); each recording here is one window, and one is left out at a time to "
            "test"
        )
    return None
