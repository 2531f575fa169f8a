"""The scene library on disk: `ROOT/<scene>/**/<recording or picture>`.

Each audio file is one *recording* and keeps its identity (the evaluation protocols split by
recording); each image file is one *picture*. Files are found at any depth below `<scene>/`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from servant_core.audio import (
    AUDIO_SUFFIXES,
    DEFAULT_RATE,
    DEFAULT_WINDOW_SECONDS,
    cut_windows,
    read_audio,
)
from servant_core.errors import ServantError

PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True)
class Recording:
    scene: str
    path: Path


@dataclass(frozen=True)
class Picture:
    scene: str
    path: Path


@dataclass
class SceneLibrary:
    root: Path
    scenes: list[str]
    recordings: list[Recording] = field(default_factory=list)
    pictures: list[Picture] = field(default_factory=list)

    @classmethod
    def scan(cls, root: str | Path) -> SceneLibrary:
        """List every scene folder of `root` and the recordings and pictures below it (sorted)."""
        root = Path(root)
        if not root.is_dir():
            raise ServantError(f"{root}: no such scene library (expected ROOT/<scene>/<files>)")
        scenes: list[str] = []
        recordings: list[Recording] = []
        pictures: list[Picture] = []
        for scene_dir in sorted(
            p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")
        ):
            scenes.append(scene_dir.name)
            for path in sorted(scene_dir.rglob("*")):
                if path.name.startswith(".") or not path.is_file():
                    continue
                suffix = path.suffix.lower()
                if suffix in AUDIO_SUFFIXES:
                    recordings.append(Recording(scene_dir.name, path))
                elif suffix in PICTURE_SUFFIXES:
                    pictures.append(Picture(scene_dir.name, path))
        return cls(root, scenes, recordings, pictures)

    def restricted(self, scenes: Sequence[str]) -> SceneLibrary:
        """The same library with only the named scenes (unknown names are an error)."""
        missing = sorted(set(scenes) - set(self.scenes))
        if missing:
            raise ServantError(f"{self.root}: no scene folder named {', '.join(missing)}")
        keep = set(scenes)
        return SceneLibrary(
            self.root,
            [s for s in self.scenes if s in keep],
            [r for r in self.recordings if r.scene in keep],
            [p for p in self.pictures if p.scene in keep],
        )


@dataclass
class WindowFeatures:
    """Per-window features of a set of recordings, each row tagged with its scene and recording."""

    features: np.ndarray  # (n, ...) as the method's featurize returns them
    scenes: np.ndarray  # (n,) str
    recording: np.ndarray  # (n,) int, index into `recordings`
    position: np.ndarray  # (n,) int, the window's index within its recording
    recordings: list[Recording]


def iter_recording_windows(
    recordings: Sequence[Recording],
    rate: int = DEFAULT_RATE,
    seconds: float = DEFAULT_WINDOW_SECONDS,
    on_error: Callable[[ServantError], None] | None = None,
) -> Iterator[tuple[int, Recording, np.ndarray]]:
    """Yield (index, recording, windows) one recording at a time, so memory holds one only.

    A recording that cannot be read, or is shorter than one window, is passed to `on_error`
    (and skipped) when given; otherwise it raises.
    """
    for index, recording in enumerate(recordings):
        try:
            windows = cut_windows(read_audio(recording.path, rate), rate, seconds)
            if len(windows) == 0:
                raise ServantError(
                    f"{recording.path}: shorter than one {seconds:g} s window; record longer"
                )
        except ServantError as error:
            if on_error is None:
                raise
            on_error(error)
            continue
        yield index, recording, windows


def featurize_recordings(
    recordings: Sequence[Recording],
    featurize: Callable[[np.ndarray], np.ndarray],
    rate: int = DEFAULT_RATE,
    seconds: float = DEFAULT_WINDOW_SECONDS,
    on_error: Callable[[ServantError], None] | None = None,
) -> WindowFeatures:
    """Cut every recording into windows and featurize them, one recording at a time."""
    parts: list[np.ndarray] = []
    scenes: list[str] = []
    rec_ids: list[int] = []
    positions: list[int] = []
    for index, recording, windows in iter_recording_windows(recordings, rate, seconds, on_error):
        parts.append(featurize(windows))
        scenes += [recording.scene] * len(windows)
        rec_ids += [index] * len(windows)
        positions += range(len(windows))
    if not parts:
        raise ServantError("no usable recording: every audio file was unreadable or too short")
    return WindowFeatures(
        _concatenate_releasing(parts),
        np.array(scenes),
        np.array(rec_ids),
        np.array(positions),
        list(recordings),
    )


def _concatenate_releasing(parts: list[np.ndarray]) -> np.ndarray:
    """np.concatenate that frees each part once copied, so memory never holds both in full
    (the paper's FFT vectors of a whole library are hundreds of megabytes)."""
    out = np.empty((sum(len(p) for p in parts), *parts[0].shape[1:]), dtype=parts[0].dtype)
    start = 0
    while parts:
        part = parts.pop(0)
        out[start : start + len(part)] = part
        start += len(part)
    return out


def read_picture(path: str | Path) -> np.ndarray:
    """Read a picture as a BGR uint8 array (OpenCV's order); a non-picture raises ServantError."""
    path = Path(path)
    data = np.fromfile(str(path), dtype=np.uint8) if path.is_file() else None
    if data is None:
        raise ServantError(f"{path}: no such picture")
    image = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if image is None:
        raise ServantError(f"{path}: not a picture OpenCV can read; use PNG or JPEG")
    return image


def read_pictures(
    pictures: Sequence[Picture], on_error: Callable[[ServantError], None] | None = None
) -> tuple[list[np.ndarray], list[Picture]]:
    """Read pictures, skipping (and reporting through `on_error`) those that cannot be read."""
    images: list[np.ndarray] = []
    kept: list[Picture] = []
    for picture in pictures:
        try:
            images.append(read_picture(picture.path))
        except ServantError as error:
            if on_error is None:
                raise
            on_error(error)
            continue
        kept.append(picture)
    return images, kept
