"""Both recognisers fitted on one library, for the fusion evaluation and the paper's tables:
the scenes that have recordings and pictures, sound on its temporal split and pictures on their
file-order split."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from servant_core.choices import IMAGE_TRAIN_FRACTION
from servant_core.errors import ServantError
from servant_core.evaluate.audio import featurize_library_audio
from servant_core.evaluate.image import featurize_pictures
from servant_core.evaluate.splits import file_order_split, temporal_split
from servant_core.library import Picture, SceneLibrary, WindowFeatures, visits_of
from servant_core.recognisers import (
    AcousticRecogniser,
    Recogniser,
    make_audio_recogniser,
    make_recogniser,
)
from servant_core.recognisers.base import fit_visits


def paired_scenes(
    library: SceneLibrary, test_library: SceneLibrary | None, needs: str
) -> list[str]:
    """The sorted scenes with both recordings and pictures in `library` (and in `test_library`,
    if given); at least two, or a ServantError that says what `needs` them."""
    paired = sorted({r.scene for r in library.recordings} & {p.scene for p in library.pictures})
    if test_library is not None:
        paired = [
            s
            for s in paired
            if any(r.scene == s for r in test_library.recordings)
            and any(p.scene == s for p in test_library.pictures)
        ]
    if len(paired) < 2:
        raise ServantError(
            f"{library.root}: {needs} at least two scenes with both recordings and pictures"
        )
    return paired


@dataclass
class PairedFit:
    """Both recognisers fitted on one library, and what they were fitted on."""

    audio: AcousticRecogniser
    windows: WindowFeatures
    window_train: np.ndarray  # which of `windows` trained `audio`
    visual: Recogniser
    picture_features: np.ndarray  # rows of `pictures`
    pictures: list[Picture]  # the readable pictures
    picture_train: np.ndarray  # which of `pictures` trained `visual`


def fit_paired(
    library: SceneLibrary,
    acoustic_method: str,
    visual_method: str,
    on_error: Callable[[ServantError], None] | None,
    train_on_all: bool = False,
    on_progress: Callable[[str], Callable[[int, int], None]] | None = None,
) -> PairedFit:
    """The acoustic recogniser trained on the temporal split of the library's windows, the visual
    one on the file-order split of its pictures; on all of both with `train_on_all` (when the
    test items come from another library). `on_progress(step)` gives the callback of each step
    ("listening to recordings", "reading pictures")."""
    audio = make_audio_recogniser(acoustic_method)
    heard = on_progress("listening to recordings") if on_progress else None
    wf = featurize_library_audio(library, audio, on_error, heard)
    train = (
        np.ones(len(wf.scenes), bool) if train_on_all else temporal_split(wf.recording, wf.position)
    )
    fit_visits(audio, wf.features[train], wf.scenes[train], visits_of(wf)[train])
    visual = make_recogniser("image", visual_method)
    seen = on_progress("reading pictures") if on_progress else None
    X, kept = featurize_pictures(visual, library.pictures, on_error, seen)
    p_train = (
        np.ones(len(kept), bool) if train_on_all else file_order_split(kept, IMAGE_TRAIN_FRACTION)
    )
    visual.fit(X[p_train], [p.scene for p, t in zip(kept, p_train, strict=True) if t])
    return PairedFit(audio, wf, train, visual, X, kept, p_train)
