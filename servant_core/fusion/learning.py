"""What the learned fusion learns from: each sense's opinions of items its recogniser never saw.

The training items of each sense are cut into `k` folds; a fresh copy of its recogniser (same
parameters) is fitted on all folds but one and gives its opinions on that one, in turn
(cross-validated predictions). The folds are a recording's windows in contiguous blocks of time
(never split between fitting and judging when it can be helped), pictures in blocks of file
order within each scene. The net then reuses the same folds to choose its threshold.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from servant_core.errors import ServantError
from servant_core.fusion.net import FusionNet, SenseOpinions
from servant_core.library import Picture, WindowFeatures, visits_of
from servant_core.recognisers.base import (
    Recogniser,
    fit_visits,
    init_params,
    open_probabilities,
)

DEFAULT_FOLDS = 4


def contiguous_folds(recording: np.ndarray, position: np.ndarray, k: int) -> np.ndarray:
    """The fold (0..k-1) of each window: each recording's windows cut into `k` contiguous blocks
    in time order (fewer when it has fewer than `k` windows)."""
    fold = np.zeros(len(position), dtype=int)
    for r in np.unique(recording):
        rows = np.flatnonzero(recording == r)
        ordered = rows[np.argsort(position[rows], kind="stable")]
        fold[ordered] = np.arange(len(ordered)) * k // len(ordered)
    return fold


def order_folds(scenes: Sequence[str] | np.ndarray, k: int) -> np.ndarray:
    """The fold (0..k-1) of each item: each scene's items, in the order given, cut into `k`
    contiguous blocks."""
    scenes = np.asarray(scenes)
    fold = np.zeros(len(scenes), dtype=int)
    for scene in np.unique(scenes):
        rows = np.flatnonzero(scenes == scene)
        fold[rows] = np.arange(len(rows)) * k // len(rows)
    return fold


def fresh_copy(recogniser: Recogniser) -> Recogniser:
    """An unfitted recogniser with the same parameters."""
    return type(recogniser)(**init_params(recogniser))


def held_out_opinions(
    make_model: Callable[[], Recogniser],
    X: np.ndarray,
    scenes: Sequence[str] | np.ndarray,
    fold: np.ndarray,
    visits: np.ndarray | None = None,
) -> SenseOpinions:
    """Each item's opinion from a model fitted on the other folds (told the `visits` of its
    rows, where it learns them). A fold whose complement cannot be fitted (fewer than two
    scenes) gives no opinions; its items are left out."""
    scenes = np.asarray(scenes)
    columns = sorted(set(scenes.tolist()))
    proba = np.zeros((len(scenes), len(columns)))
    predicted = np.empty(len(scenes), dtype=object)
    judged = np.zeros(len(scenes), dtype=bool)
    for f in np.unique(fold):
        test = fold == f
        try:
            kept = None if visits is None else visits[~test]
            model = fit_visits(make_model(), X[~test], scenes[~test], kept)
        except ServantError:
            continue
        index = [columns.index(s) for s in model.scenes_]
        proba[np.ix_(test, index)] = open_probabilities(model, X[test])
        predicted[test] = model.predict(X[test])
        judged |= test
    return SenseOpinions(
        proba[judged], columns, predicted[judged].astype(str), scenes[judged], fold[judged]
    )


def window_opinions(
    recogniser: Recogniser, windows: WindowFeatures, folds: int = DEFAULT_FOLDS
) -> SenseOpinions:
    """Held-out opinions of `windows` from fresh copies of `recogniser` (fitted or not: only
    its parameters are used), folds in contiguous blocks of time within each recording."""
    return held_out_opinions(
        lambda: fresh_copy(recogniser),
        windows.features,
        windows.scenes,
        contiguous_folds(windows.recording, windows.position, folds),
        visits_of(windows),
    )


def picture_opinions(
    recogniser: Recogniser, X: np.ndarray, pictures: Sequence[Picture], folds: int = DEFAULT_FOLDS
) -> SenseOpinions:
    """Held-out opinions of the pictures featurized as rows of `X`, folds in blocks of file
    name order within each scene."""
    order = np.argsort([p.path.name for p in pictures], kind="stable")
    scenes = np.array([pictures[i].scene for i in order])
    return held_out_opinions(
        lambda: fresh_copy(recogniser), X[order], scenes, order_folds(scenes, folds)
    )


def train_fusion_net(
    opinions: Mapping[str, SenseOpinions], **params: Any
) -> tuple[FusionNet | None, str | None]:
    """A `FusionNet(**params)` fitted on `opinions`, or (None, why) when they are too little to
    learn from: the caller then keeps a rule policy and may say why."""
    net = FusionNet(**params)
    reason = net.shortfall(opinions)
    if reason is not None:
        return None, reason
    net.fit(opinions)
    if net.threshold_ >= 1.0:
        return None, (
            f"the learned fusion was never right {net.target_precision:.0%} of the time on "
            "held-out items; teach more"
        )
    return net, None
