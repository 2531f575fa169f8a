"""The scene library on disk: `ROOT/<scene>/**/<recording or picture>`.

Each audio file is one *recording* and keeps its identity (the evaluation protocols split by
recording); each image file is one *picture*. Files are found at any depth below `<scene>/`.
Teach mode's recordings, pictures and sample logs are written here (`SceneLibrary.add_*`), each
atomically; a write adds a file on disk, not to a listing already scanned.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import cv2
import numpy as np

from servant_core.audio import (
    AUDIO_SUFFIXES,
    DEFAULT_RATE,
    DEFAULT_WINDOW_SECONDS,
    cut_windows,
    read_audio,
    write_wav,
)
from servant_core.errors import ServantError
from servant_core.features.rows import usable_rows
from servant_core.place_names import place_name
from servant_core.senses import PICTURE_SUFFIXES, SAMPLE_SENSES, UNKNOWN
from servant_core.storage import (
    atomic_write_bytes,
    atomic_write_text,
    open_regular_file,
    os_reason,
    walk_files,
)

# A webcam frame is under 1 Mpx and a phone photo under 50 Mpx; a header claiming more is
# damaged or hostile (a 1 MB PNG can claim gigabytes). Checked before decoding.
MAX_PICTURE_PIXELS = 50_000_000
MAX_PICTURE_BYTES = 64 * 1024 * 1024
# The windows of sound teach mode asks for a place: six presses of *Record 5 s*, 30 s
# (docs/research.md).
TEACH_WINDOWS = 6
# One-window recordings of a place (teach mode's presses, windows labelled live) made no more than
# this apart are one visit (`visits_of`).
VISIT_GAP_SECONDS = 30 * 60

ProgressCallback = Callable[[int, int], None]
"""`on_progress(done, total)`: called after each file of a long step (done counts from 1)."""


@dataclass(frozen=True)
class Recording:
    scene: str
    path: Path


@dataclass(frozen=True)
class Picture:
    scene: str
    path: Path


@dataclass(frozen=True)
class SampleFile:
    """A log of a sample sense's readings (`*.imu.csv`, `*.ambient.csv`: `capture.sample_files`)."""

    scene: str
    path: Path


@dataclass
class SceneLibrary:
    root: Path
    scenes: list[str]
    recordings: list[Recording] = field(default_factory=list)
    pictures: list[Picture] = field(default_factory=list)
    # each sample sense's logs, by sense name ("motion", "ambient"); senses without any left out
    samples: dict[str, list[SampleFile]] = field(default_factory=dict)

    @classmethod
    def scan(cls, root: str | Path) -> SceneLibrary:
        """List every scene folder of `root` and the recordings and pictures below it (sorted)."""
        root = Path(root)
        if not root.is_dir():
            raise ServantError(f"{root}: no such scene library (expected ROOT/<scene>/<files>)")
        try:
            return cls._scan(root)
        except OSError as exc:
            raise ServantError(
                f"{exc.filename or root}: cannot read the scene library ({os_reason(exc)})"
            ) from None

    @classmethod
    def _scan(cls, root: Path) -> SceneLibrary:
        scenes: list[str] = []
        recordings: list[Recording] = []
        pictures: list[Picture] = []
        samples: dict[str, list[SampleFile]] = {}
        for scene_dir in sorted(
            p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")
        ):
            if scene_dir.name == UNKNOWN:
                raise ServantError(
                    f"{scene_dir}: the scene name {UNKNOWN} means a place Servant does not know "
                    "and can never be detected; rename the folder"
                )
            scenes.append(scene_dir.name)
            for path in walk_files(scene_dir):
                if path.name.startswith(".") or not path.is_file():
                    continue
                suffix = path.suffix.lower()
                if suffix in AUDIO_SUFFIXES:
                    recordings.append(Recording(scene_dir.name, path))
                elif suffix in PICTURE_SUFFIXES:
                    pictures.append(Picture(scene_dir.name, path))
                else:
                    for sense in SAMPLE_SENSES.values():
                        if path.name.lower().endswith(sense.suffixes):
                            samples.setdefault(sense.name, []).append(
                                SampleFile(scene_dir.name, path)
                            )
        return cls(root, scenes, recordings, pictures, samples)

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
            {sense: [f for f in files if f.scene in keep] for sense, files in self.samples.items()},
        )

    @classmethod
    def at(cls, root: str | Path) -> SceneLibrary:
        """The library at `root` to write into, unlisted: its folder need not exist yet."""
        return cls(Path(root), [])

    def add_recording(
        self, scene: str, window: np.ndarray, rate: int, stem: str | None = None
    ) -> Path:
        """Write mono float sound at `rate` as `<scene>/<stem>.wav` (16-bit); the file."""
        return self._add(
            scene, stem, ".wav", "recording", lambda path: write_wav(path, window, rate)
        )

    def add_picture(self, scene: str, frame: np.ndarray, stem: str | None = None) -> Path:
        """Write a BGR uint8 picture as `<scene>/<stem>.png`; the file."""
        ok, png = cv2.imencode(".png", frame)
        if not ok:
            raise ServantError("camera: the picture could not be encoded; try again")
        return self._add(
            scene, stem, ".png", "picture", lambda path: atomic_write_bytes(path, png.tobytes())
        )

    def add_samples(
        self,
        scene: str,
        sense: str,
        rows: np.ndarray,
        rate: int,
        channels: Sequence[str],
        stem: str | None = None,
    ) -> Path:
        """Write a sample sense's (n, channels) readings at `rate` as its log,
        `<scene>/<stem>.<stream>.csv` (`channels` name its columns); the file."""
        text = sample_log_text(rows, rate, channels)
        suffix = SAMPLE_SENSES[sense].suffixes[0]
        return self._add(
            scene, stem, suffix, f"{sense} log", lambda path: atomic_write_text(path, text)
        )

    def _add(
        self, scene: str, stem: str | None, suffix: str, what: str, write: Callable[[Path], Path]
    ) -> Path:
        """`write(path)` for a new file of the scene's folder, its name `<stem><suffix>` (a
        teach stamp when no stem is given). Every write is atomic (a temporary file, then
        `os.replace`): one that fails leaves no part of the file and keeps what was there, and
        is one ServantError. `scene` is a place's name by `place_name`: a folder already there
        matching it is that place, in its spelling."""
        name = f"{stem or teach_stem()}{suffix}"
        if name != Path(name).name or name.startswith("."):
            raise ValueError(f"{name!r}: not a plain, visible file name")
        folder = self.root / place_name(scene, self.root)
        try:
            return write(folder / name)
        except OSError as exc:
            raise ServantError(
                f"{folder / name}: the {what} cannot be written ({os_reason(exc)}); "
                "make room or fix the folder, then try again"
            ) from None


def teach_stem(now: datetime | None = None) -> str:
    """The name teach mode gives the files of one recording or picture: its time, to the
    microsecond (`teach-20250314-093015-123456`)."""
    return (now or datetime.now()).strftime("teach-%Y%m%d-%H%M%S-%f")


def sample_log_text(
    samples: np.ndarray, rate: int, channels: Sequence[str], start: float = 0.0
) -> str:
    """(n, channels) readings at `rate` as a sample log's CSV: a header `time,<channels>`,
    then a row a reading (`capture.sample_files` reads it back)."""
    samples = np.asarray(samples)
    if samples.ndim != 2 or samples.shape[1] != len(channels):
        raise ValueError(f"expected (n, {len(channels)}) samples")
    lines = [",".join(("time", *channels))]
    for i, row in enumerate(samples):
        values = ",".join(f"{float(x):.4f}" for x in row)
        lines.append(f"{start + i / rate:.4f},{values}")
    return "\n".join(lines) + "\n"


@dataclass
class WindowFeatures:
    """Per-window features of a set of recordings, each row tagged with its scene and recording."""

    features: np.ndarray  # (n, ...) as the method's featurize returns them
    scenes: np.ndarray  # (n,) str
    recording: np.ndarray  # (n,) int, index into `recordings`
    position: np.ndarray  # (n,) int, the window's index within its recording
    recordings: list[Recording]


def visits_of(wf: WindowFeatures) -> np.ndarray:
    """(n,) int: the visit each window comes from, for a recogniser that learns a place's visits
    apart (`kmeans-encoder`). A recording longer than one window is a visit of its own (a file
    of a library, recorded in one go). One-window recordings of a place, teach mode's presses,
    are one visit while each was made within `VISIT_GAP_SECONDS` of the one before (by their
    files' modification times): three presses at the café are one visit, a press there a week
    later another. A file whose time cannot be read is a visit of its own."""
    windows = np.bincount(wf.recording, minlength=len(wf.recordings))
    visit = np.arange(len(wf.recordings))
    presses: dict[str, list[tuple[float, int]]] = {}
    for index in np.flatnonzero(windows == 1).tolist():
        recording = wf.recordings[index]
        try:
            made = recording.path.stat().st_mtime
        except OSError:
            continue
        presses.setdefault(recording.scene, []).append((made, index))
    for made_at in presses.values():
        made_at.sort()
        for (before, previous), (made, index) in zip(made_at, made_at[1:], strict=False):
            if made - before <= VISIT_GAP_SECONDS:
                visit[index] = visit[previous]
    return visit[wf.recording]


def iter_recording_windows(
    recordings: Sequence[Recording],
    rate: int = DEFAULT_RATE,
    seconds: float = DEFAULT_WINDOW_SECONDS,
    on_error: Callable[[ServantError], None] | None = None,
    on_progress: ProgressCallback | None = None,
) -> Iterator[tuple[int, Recording, np.ndarray]]:
    """Yield (index, recording, windows) one recording at a time, so memory holds one only.

    A recording that cannot be read, or is shorter than one window, is passed to `on_error`
    (and skipped) when given; otherwise it raises. `on_progress(done, total)` is called once
    each recording is done with: skipped, or after the caller has used its windows.
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
        else:
            yield index, recording, windows
        if on_progress is not None:
            on_progress(index + 1, len(recordings))


def featurize_recordings(
    recordings: Sequence[Recording],
    featurize: Callable[[np.ndarray], np.ndarray],
    rate: int = DEFAULT_RATE,
    seconds: float = DEFAULT_WINDOW_SECONDS,
    on_error: Callable[[ServantError], None] | None = None,
    on_progress: ProgressCallback | None = None,
) -> WindowFeatures:
    """Cut every recording into windows and featurize them, one recording at a time.

    `on_progress(done, total)` is called after each recording (skipped ones count as done).
    """
    parts: list[np.ndarray] = []
    scenes: list[str] = []
    rec_ids: list[int] = []
    positions: list[int] = []
    for index, recording, windows in iter_recording_windows(
        recordings, rate, seconds, on_error, on_progress
    ):
        X = featurize(windows)
        usable = usable_rows(X)
        if not np.all(usable):
            error = ServantError(
                f"{recording.path}: {np.count_nonzero(~usable)} of {len(usable)} windows give "
                "features that are not finite numbers; the file is damaged, record it again"
            )
            if on_error is None:
                raise error
            on_error(error)  # and the recording's other windows are used
        parts.append(X[usable])
        scenes += [recording.scene] * int(np.count_nonzero(usable))
        rec_ids += [index] * int(np.count_nonzero(usable))
        positions += np.flatnonzero(usable).tolist()
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
    """Read a PNG or JPEG picture as a BGR uint8 array (OpenCV's order).

    Its size is read from the header before decoding; anything else, or a picture over
    MAX_PICTURE_PIXELS, raises one clear ServantError.
    """
    path = Path(path)
    with open_regular_file(path, "picture") as handle:
        try:
            data = handle.read(MAX_PICTURE_BYTES + 1)
        except OSError as exc:
            raise ServantError(f"{path}: cannot read the picture ({exc.strerror})") from None
    if len(data) > MAX_PICTURE_BYTES:
        raise ServantError(
            f"{path}: larger than {MAX_PICTURE_BYTES >> 20} MB; use a smaller picture"
        )
    size = picture_size(data)
    if size is None:
        raise ServantError(f"{path}: not a PNG or JPEG picture (or a damaged one); use PNG or JPEG")
    width, height = size
    if width * height > MAX_PICTURE_PIXELS:
        raise ServantError(
            f"{path}: {width}×{height} pixels is more than {MAX_PICTURE_PIXELS // 1_000_000} "
            "megapixels (a damaged header?); use a smaller picture"
        )
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    except cv2.error:
        image = None
    if image is None or image.size == 0:
        raise ServantError(f"{path}: a damaged picture OpenCV cannot decode; take it again")
    return image


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# JPEG start-of-frame markers (baseline, progressive, lossless, arithmetic): they carry the size.
JPEG_FRAME_MARKERS = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def picture_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG or JPEG header without decoding it; None for anything else
    (OpenCV would decode other formats by content whatever the file is called)."""
    if data.startswith(PNG_SIGNATURE):
        if len(data) < 24 or data[12:16] != b"IHDR":
            return None
        width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
        return (width, height) if width and height else None
    if not data.startswith(b"\xff\xd8"):
        return None
    at = 2
    while at + 4 <= len(data):
        if data[at] != 0xFF:
            return None
        marker = data[at + 1]
        if marker == 0xFF:  # fill byte
            at += 1
            continue
        if marker in (0x01, *range(0xD0, 0xD8)):  # markers without a length
            at += 2
            continue
        length = int.from_bytes(data[at + 2 : at + 4], "big")
        if marker in JPEG_FRAME_MARKERS:
            if length < 7 or at + 9 > len(data):
                return None
            height = int.from_bytes(data[at + 5 : at + 7], "big")
            width = int.from_bytes(data[at + 7 : at + 9], "big")
            return (width, height) if width and height else None
        if marker == 0xDA or length < 2:  # image data before any frame header
            return None
        at += 2 + length
    return None


def read_pictures(
    pictures: Sequence[Picture],
    on_error: Callable[[ServantError], None] | None = None,
    on_progress: ProgressCallback | None = None,
) -> tuple[list[np.ndarray], list[Picture]]:
    """Read pictures, skipping (and reporting through `on_error`) those that cannot be read;
    `on_progress(done, total)` after each."""
    images: list[np.ndarray] = []
    kept: list[Picture] = []
    for done, picture in enumerate(pictures, start=1):
        try:
            images.append(read_picture(picture.path))
        except ServantError as error:
            if on_error is None:
                raise
            on_error(error)
        else:
            kept.append(picture)
        if on_progress is not None:
            on_progress(done, len(pictures))
    return images, kept
