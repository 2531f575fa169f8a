"""Scoring a picture recogniser: a train library and a test library, or one library split by
file order per scene (`evaluate_image`, `servant eval image`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from servant_core.choices import IMAGE_TRAIN_FRACTION
from servant_core.errors import ServantError
from servant_core.evaluate.metrics import Predictions, over_seeds, scores, seeded_params
from servant_core.evaluate.splits import file_order_split
from servant_core.library import Picture, SceneLibrary, read_pictures
from servant_core.recognisers import Recogniser, make_recogniser


def featurize_pictures(
    model: Recogniser,
    pictures: Sequence[Picture],
    on_error: Callable[[ServantError], None] | None,
    on_progress: Callable[[int, int], None] | None = None,
) -> tuple[np.ndarray, list[Picture]]:
    """The readable `pictures` and their features as `model` sees them; none readable is a
    ServantError."""
    images, kept = read_pictures(pictures, on_error, on_progress)
    if not kept:
        raise ServantError("no readable picture")
    return model.featurize(images), kept


def evaluate_image(
    train_library: SceneLibrary,
    test_library: SceneLibrary | None = None,
    method: str = "paper",
    split: float = IMAGE_TRAIN_FRACTION,
    params: dict[str, Any] | None = None,
    on_error: Callable[[ServantError], None] | None = None,
    seeds: int = 1,
) -> dict[str, Any]:
    """Train on `train_library`'s pictures and test on `test_library`'s; with no test library,
    split each scene's pictures by file order (the first `split` train). With `seeds` > 1 the
    figures are means over random states 0..seeds-1 (see `over_seeds`); pictures are featurized
    once (featurizing depends on the parameters only)."""
    params = params or {}
    model = make_recogniser("image", method, **params)
    if test_library is None:
        X, kept = featurize_pictures(model, train_library.pictures, on_error)
        train = file_order_split(kept, split)
        X_train, y_train = X[train], [p.scene for p, t in zip(kept, train, strict=True) if t]
        X_test, y_test = X[~train], [p.scene for p, t in zip(kept, train, strict=True) if not t]
        protocol = f"file-order-{split:g}"
        if not y_test:
            raise ServantError(
                f"{train_library.root}: nothing to evaluate: the file-order split keeps every "
                "picture for training (a scene needs two pictures or more); take more pictures "
                "or give a test library (--test)"
            )
    else:
        X_train, kept_train = featurize_pictures(model, train_library.pictures, on_error)
        X_test, kept_test = featurize_pictures(model, test_library.pictures, on_error)
        y_train = [p.scene for p in kept_train]
        y_test = [p.scene for p in kept_test]
        protocol = "train-test"

    def run(seed: int | None) -> dict[str, Any]:
        fitted = make_recogniser("image", method, **seeded_params(params, method, "image", seed))
        fitted.fit(X_train, y_train)
        preds = Predictions([], [], [])
        preds.extend(fitted, X_test, y_test)
        return scores(preds, sorted(set(y_train) | set(y_test)))

    result = over_seeds(run, seeds)
    result.update(method=method, protocol=protocol, sense="image", n_train=len(y_train))
    return result
