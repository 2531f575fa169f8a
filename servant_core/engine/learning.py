"""The learning part of the engine: refitting on a library, keeping unknowns, folding in a label,
and saving the result.

These are the pieces; `models.Models` holds the locks and swaps the new recognisers in (and
`unknown_places.UnknownPlaces` keeps the unknowns). Every update is made on a copy, so the
sense thread, which may be predicting with the old recogniser right now, never sees half of one.
"""

from __future__ import annotations

import copy
import functools
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from servant_core.audio import resample, write_wav
from servant_core.capture.sample_files import cut_sample_windows, read_samples, write_sample_csv
from servant_core.errors import ServantError
from servant_core.features.rows import checked_rows, usable_rows
from servant_core.fusion.learning import (
    DEFAULT_FOLDS,
    fresh_copy,
    held_out_opinions,
    order_folds,
    picture_opinions,
    train_fusion_net,
    window_opinions,
)
from servant_core.fusion.net import FusionNet, SenseOpinions
from servant_core.library import (
    SampleFile,
    SceneLibrary,
    featurize_recordings,
    read_pictures,
    visits_of,
)
from servant_core.modelfile import save_model
from servant_core.recognisers import Recogniser, make_recogniser
from servant_core.recognisers.background import kept_out
from servant_core.recognisers.base import fit_visits
from servant_core.senses import SAMPLE_SENSES, SENSES
from servant_core.storage import atomic_write_bytes, os_reason

UNKNOWN_KEPT = 16  # unknown windows/pictures kept for the user to label, the oldest dropped first

OnError = Callable[[ServantError], None]
OnProgress = Callable[[int, int], None]


@dataclass
class Kept:
    """An unknown window or picture, held until the user labels it."""

    sense: str  # "audio", "image", or a sample sense ("motion": readings (n, channels))
    data: np.ndarray
    rate: int = 0  # samples (or readings) a second; 0 for a picture
    # the sound's windows just before `data` that named no taught place either, oldest first:
    # the place the wearer is asked about, heard for longer than one window (shared, not copied)
    before: tuple[np.ndarray, ...] = ()

    @property
    def windows(self) -> tuple[np.ndarray, ...]:
        """Every window the label is for, oldest first."""
        return (*self.before, self.data)


class Unknowns:
    """The last `UNKNOWN_KEPT` unknown windows and pictures, by id ("audio-3"), thread-safe."""

    def __init__(self) -> None:
        self._kept: OrderedDict[str, Kept] = OrderedDict()
        self._count = 0
        self._labelling: set[str] = set()
        self._lock = threading.Lock()

    def keep(self, kept: Kept) -> str:
        with self._lock:
            self._count += 1
            window_id = f"{kept.sense}-{self._count}"
            self._kept[window_id] = kept
            # the oldest go first, but not one whose label is being written: if that write
            # fails, the label can still be given again
            idle = [w for w in self._kept if w not in self._labelling]
            for oldest in idle[: max(len(self._kept) - UNKNOWN_KEPT, 0)]:
                del self._kept[oldest]
        return window_id

    @contextmanager
    def labelling(self, window_id: str) -> Iterator[Kept]:
        """The window, given up only when the block ends without an error (its label written):
        one whose write failed can be labelled again. While a label is being written the window
        is not given to another."""
        with self._lock:
            kept = self._kept.get(window_id)
            busy = window_id in self._labelling
            if kept is not None and not busy:
                self._labelling.add(window_id)
        if kept is None:
            raise ServantError(
                f"{window_id}: no such unknown window (only the last {UNKNOWN_KEPT} are kept)"
            )
        if busy:
            raise ServantError(f"{window_id}: a label for it is being written; wait for it")
        written = False
        try:
            yield kept
            written = True
        finally:
            with self._lock:
                self._labelling.discard(window_id)
                if written:
                    self._kept.pop(window_id, None)


def copy_or_fresh(recogniser: Recogniser | None, sense: str, method: str) -> Any:
    """A copy of `recogniser` to refit, or a new one of `method` for a sense that has none."""
    if recogniser is not None:
        return copy.deepcopy(recogniser)
    return make_recogniser(sense, method)


def retrained(
    library: SceneLibrary,
    current: Mapping[str, Recogniser],
    fresh_methods: Mapping[str, str],
    window_seconds: float,
    on_error: OnError,
    on_progress: OnProgress | None = None,
) -> tuple[dict[str, Recogniser], list[ServantError]]:
    """({sense: refitted recogniser}, why others could not be) for each sense with files in
    the library: a copy of its `current` recogniser refitted, or a new one of its fresh method.
    Sound first, then pictures, then each sample sense. `on_progress` follows each sense in
    two phases, as the bar's estimate can: its files read, `(done, files)`, then its fit, `(0,
    1)` and `(1, 1)` (a fit has no steps of its own; on a teach-mode library it is most of the
    time, so one bar over the files alone sat full for most of the retrain)."""
    parts: list[tuple[str, Sequence[Any]]] = [
        ("audio", library.recordings),
        ("image", library.pictures),
        *library.samples.items(),
    ]
    fitted: dict[str, Recogniser] = {}
    failures: list[ServantError] = []
    for sense, files in parts:
        if not files:
            continue
        lacking = too_few_scenes(sense, files, library)
        if lacking is not None:
            failures.append(lacking)
            continue
        model = copy_or_fresh(current.get(sense), sense, fresh_methods[sense])
        progress = fitting_after_reading(on_progress, len(files))
        try:
            if sense == "audio":
                new = refit_audio(library, model, window_seconds, on_error, progress)
            elif sense == "image":
                new = refit_pictures(library, model, on_error, progress)
            else:
                stream = SAMPLE_SENSES[sense].stream or sense
                new = refit_samples(files, stream, model, window_seconds, on_error, progress)
        except ServantError as error:
            failures.append(ServantError(f"retrain ({sense_words(sense)}): {error}"))
            continue
        if on_progress is not None:
            on_progress(1, 1)
        if new is not None:
            fitted[sense] = new
    return fitted, failures


RETRAIN_WORDS = {"audio": "sound", "image": "pictures"}
# What teach mode's buttons do, for a sense that lacks a place (sample senses record with sound).
TEACH_WORDS = {"audio": "record sound at", "image": "take pictures of"}


def sense_words(sense: str) -> str:
    return RETRAIN_WORDS.get(sense, SENSES[sense].label if sense in SENSES else sense)


def too_few_scenes(sense: str, files: Sequence[Any], library: SceneLibrary) -> ServantError | None:
    """Why `files` (one sense's) cannot train it, in teach mode's words, naming the places that
    lack them ("take pictures of street"); None when two places or more have some."""
    have = sorted({f.scene for f in files})
    if len(have) >= 2:
        return None
    lacking = [scene for scene in library.scenes if scene not in have]
    words = sense_words(sense)
    fix = (
        f"{TEACH_WORDS.get(sense, f'record {words} at')} {', '.join(lacking)}"
        if lacking
        else "teach a second place"
    )
    return ServantError(
        f"{words}: only {have[0]} has any, nothing to tell it apart from; {fix} in teach mode "
        "(key t), then retrain"
    )


def retrained_text(senses: Sequence[str] | None, library: SceneLibrary) -> str:
    """What a retrain retrained, for the log: "sound and pictures retrained on cafe, street";
    `senses` None (an engine that does not say): every sense with files in the library."""
    by_sense: dict[str, Sequence[Any]] = {
        "audio": library.recordings,
        "image": library.pictures,
        **library.samples,
    }
    if senses is None:
        senses = [sense for sense, files in by_sense.items() if files]
    groups: dict[tuple[str, ...], list[str]] = {}
    for sense in senses:
        scenes = tuple(sorted({f.scene for f in by_sense.get(sense, [])}))
        groups.setdefault(scenes, []).append(sense_words(sense))
    if not groups:
        return "nothing retrained"
    said = [f"{' and '.join(words)} retrained on {', '.join(at)}" for at, words in groups.items()]
    return "; ".join(said)


def refit_audio(
    library: SceneLibrary,
    model: Any,
    window_seconds: float,
    on_error: OnError,
    on_progress: OnProgress | None = None,
) -> Any:
    """`model` fitted on the library's windows; None if the library has no recordings."""
    if not library.recordings:
        return None
    windows = featurize_recordings(
        library.recordings,
        model.featurize,
        rate=model.rate,
        seconds=window_seconds,
        on_error=on_error,
        on_progress=on_progress,
    )
    return fit_visits(
        kept_out(model, library.recordings),
        windows.features,
        list(windows.scenes),
        visits_of(windows),
    )


def refit_pictures(
    library: SceneLibrary, model: Any, on_error: OnError, on_progress: OnProgress | None = None
) -> Any:
    """`model` fitted on the library's pictures; None if there are none it can read."""
    if not library.pictures:
        return None
    images, kept = read_pictures(library.pictures, on_error=on_error, on_progress=on_progress)
    if not images:
        return None
    return model.fit(model.featurize(images), [p.scene for p in kept])


def write_labelled(root: Path, scene: str, window_id: str, kept: Kept) -> Path:
    """Write a labelled unknown into the library (`root/<scene>/`, atomically); the file. A
    write that fails (a full disk, a folder that cannot be made) is one ServantError."""
    try:
        return _write_kept(root / scene, window_id, kept)
    except OSError as exc:
        raise ServantError(
            f"{window_id}: the label {scene} cannot be written to {root / scene} "
            f"({os_reason(exc)}); make room or fix the folder, then give the label again"
        ) from None


def _write_kept(folder: Path, window_id: str, kept: Kept) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    if kept.sense == "audio":
        heard = np.concatenate(kept.windows)
        return write_wav(folder / f"heard-{stamp}-{window_id}.wav", heard, kept.rate)
    if kept.sense in SAMPLE_SENSES:
        kind = SENSES[kept.sense]
        path = folder / f"felt-{stamp}-{window_id}{kind.suffixes[0]}"
        return write_sample_csv(path, kept.data, kept.rate, str(kind.stream))
    ok, png = cv2.imencode(".png", kept.data)
    if not ok:
        raise ServantError(f"{window_id}: the picture could not be encoded as PNG")
    return atomic_write_bytes(folder / f"seen-{stamp}-{window_id}.png", png.tobytes())


def folded_in(recogniser: Any, kept: Kept, scene: str) -> Any:
    """A copy of `recogniser` (one that `folds_in`) that also knows `kept` as `scene`."""
    if kept.sense == "audio":
        X = recogniser.featurize(
            np.stack([resample(w, kept.rate, recogniser.rate) for w in kept.windows])
        )
    elif kept.sense in SAMPLE_SENSES:
        rows = resampled_rows(kept.data, kept.rate, recogniser.rate)
        X = recogniser.featurize([rows])
    else:
        X = recogniser.featurize([kept.data])
    checked_rows(X, f"{kept.sense} window")
    model = copy.deepcopy(recogniser)
    model.fold_in(X, [scene] * len(X))
    return model


def save_models(
    path: Path,
    models: Mapping[str, Recogniser | None],
    on_error: OnError,
    fusion: FusionNet | None = None,
) -> None:
    """Write the recognisers that exist (and the learned fusion's net) to `path`. A failed write
    is reported; the file keeps its previous content (atomic replace)."""
    try:
        save_model(path, {role: m for role, m in models.items() if m is not None}, fusion)
    except (OSError, ServantError) as error:
        on_error(
            ServantError(
                f"{path}: the updated model could not be saved ({error}); it is used "
                "until the program ends, and the file keeps the previous model"
            )
        )


def fitting_after_reading(on_progress: OnProgress | None, files: int) -> OnProgress | None:
    """What a sense's refit reports as it reads its `files`; once the last is read, the fit
    begins: `(0, 1)`, a phase of one step whose end the caller reports."""
    if on_progress is None:
        return None
    report = on_progress

    def progress(done: int, _total: int) -> None:
        report(done, files)
        if done >= files:
            report(0, 1)

    return progress


def sample_windows(
    files: Sequence[SampleFile],
    stream: str,
    rate: int,
    window_seconds: float,
    on_error: OnError,
    on_progress: OnProgress | None = None,
) -> tuple[list[np.ndarray], list[str]]:
    """The windows of a sample sense's logs at `rate`, in file order, and each one's scene."""
    windows: list[np.ndarray] = []
    scenes: list[str] = []
    for done, file in enumerate(files, start=1):
        try:
            cut = cut_sample_windows(read_samples(file.path, stream, rate), rate, window_seconds)
        except ServantError as error:
            on_error(error)
            cut = []
        windows += cut
        scenes += [file.scene] * len(cut)
        if on_progress is not None:
            on_progress(done, len(files))
    return windows, scenes


def refit_samples(
    files: Sequence[SampleFile],
    stream: str,
    model: Any,
    window_seconds: float,
    on_error: OnError,
    on_progress: OnProgress | None = None,
) -> Any:
    """`model` fitted on the windows of a sample sense's logs; None if none gives a window."""
    rate = int(model.rate)
    windows, scenes = sample_windows(files, stream, rate, window_seconds, on_error, on_progress)
    if not windows:
        return None
    X = model.featurize(windows)
    usable = usable_rows(X)
    if not np.all(usable):
        on_error(
            ServantError(
                f"{stream} logs: {np.count_nonzero(~usable)} of {len(usable)} windows give "
                "features that are not finite numbers; they are left out"
            )
        )
        if not np.any(usable):
            return None
    return model.fit(X[usable], [s for s, ok in zip(scenes, usable, strict=True) if ok])


def library_fusion_net(
    library: SceneLibrary,
    recognisers: Mapping[str, Any],
    window_seconds: float,
    on_error: OnError,
) -> tuple[FusionNet | None, str | None]:
    """The learned fusion's net for these recognisers ({sense: recogniser}), trained on the
    opinions fresh copies of them give of the library's items they were not fitted on (see
    `fusion.learning`); (None, why) when too little was taught."""
    opinions: dict[str, SenseOpinions] = {}
    audio, image = recognisers.get("audio"), recognisers.get("image")
    if audio is not None and library.recordings:
        rate = audio.rate
        windows = featurize_recordings(
            library.recordings, audio.featurize, rate, window_seconds, on_error
        )
        opinions["audio"] = window_opinions(audio, windows)
    if image is not None and library.pictures:
        pictures, kept = read_pictures(library.pictures, on_error=on_error)
        if pictures:
            opinions["image"] = picture_opinions(image, image.featurize(pictures), kept)
    for sense, files in library.samples.items():
        model, stream = recognisers.get(sense), SAMPLE_SENSES[sense].stream
        if model is None or stream is None:
            continue
        rate = int(model.rate)
        cut, scenes = sample_windows(files, stream, rate, window_seconds, on_error)
        if cut:
            opinions[sense] = held_out_opinions(
                functools.partial(fresh_copy, model),
                model.featurize(cut),
                scenes,
                order_folds(scenes, DEFAULT_FOLDS),
            )
    return train_fusion_net(opinions)


def resampled_rows(rows: np.ndarray, rate: int, to_rate: int) -> np.ndarray:
    """Readings (n, channels) at `rate` on a grid at `to_rate` (linear interpolation)."""
    if rate == to_rate or not len(rows):
        return rows
    t = np.arange(len(rows)) / rate
    grid = np.arange(int(len(rows) * to_rate / rate)) / to_rate
    return np.stack([np.interp(grid, t, rows[:, c]) for c in range(rows.shape[1])], axis=1)
