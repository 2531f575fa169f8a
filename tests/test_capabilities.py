"""Recognisers declare what they can do, the engine reads the declarations (issue 40): every
registered recogniser's declarations agree with what its class has, and folding in, fitting with
visits and keeping recordings out of a background go by what is declared, never by probing."""

from __future__ import annotations

import inspect
import threading
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np
import pytest

from servant_core.engine.bus import EventBus
from servant_core.engine.learning import Kept
from servant_core.engine.models import Models
from servant_core.fusion import ParallelFusion
from servant_core.fusion.pipeline import DecisionPipeline
from servant_core.recognisers import SENSE_METHODS
from servant_core.recognisers.background import kept_out
from servant_core.recognisers.base import Capabilities, TaughtPlacesOnly, fit_visits
from servant_core.recognisers.linear_head import LinearHeadAnswers

REGISTERED = sorted(
    {
        (sense, method, cls)
        for sense, methods in SENSE_METHODS.items()
        for method, cls in methods.items()
    },
    key=lambda entry: (entry[0], entry[1]),
)
IDS = [f"{sense}-{method}" for sense, method, _ in REGISTERED]


def parameters(function: Any) -> set[str]:
    return set(inspect.signature(function).parameters)


@pytest.mark.parametrize("sense,method,cls", REGISTERED, ids=IDS)
def test_every_recogniser_declares_what_it_can_do(sense: str, method: str, cls: type) -> None:
    assert issubclass(cls, Capabilities)
    folds = getattr(cls, "fold_in", None)
    assert cls.folds_in == (folds is not None and folds is not LinearHeadAnswers.fold_in)
    assert cls.learns_visits == ("visits" in parameters(cls.fit))
    assert (cls.background_path is not None) == ("background_exclude" in parameters(cls.__init__))
    # a recogniser of windows says at what rate and length it featurizes them; one of pictures
    # keeps no rate
    model = cls()
    if sense == "image":
        assert "rate" not in vars(model) and "window_seconds" not in vars(model)
    else:
        assert isinstance(model.rate, int) and model.rate > 0
        assert isinstance(model.window_seconds, float) and model.window_seconds > 0


class Told(TaughtPlacesOnly):
    """A recogniser that notes how it was fitted and folded into; what it declares is set per
    test."""

    method: ClassVar[str] = "told"
    sense: ClassVar[str] = "image"
    confidence_unit: ClassVar[str] = "%"

    def __init__(self, *, background_exclude: tuple[str, ...] = ()) -> None:
        self.background_exclude = background_exclude
        self.visits: Any = "never fitted"
        self.folded: list[str] = []
        self.scenes_ = ["cafe", "street"]

    def featurize(self, items: Any) -> np.ndarray:
        return np.ones((len(items), 2))

    def fit(self, X: np.ndarray, scenes: Any, visits: Any = None) -> Self:
        self.visits = visits
        return self

    def fold_in(self, X: np.ndarray, scenes: list[str]) -> Self:
        self.folded += scenes
        return self


def declaring(**declared: Any) -> Told:
    return type("Declared", (Told,), declared)()


@pytest.mark.parametrize("learns", [False, True])
def test_fit_visits_tells_the_visits_to_a_recogniser_that_declares_it_learns_them(learns):
    model = fit_visits(declaring(learns_visits=learns), np.ones((2, 2)), ["a", "b"], np.ones(2))
    assert (model.visits is not None) == learns


@pytest.mark.parametrize("background", [None, Path("background.npz")])
def test_recordings_are_kept_out_of_a_declared_background_only(background):
    model = kept_out(declaring(background_path=background), [Path("/a/cafe-1.wav")])
    assert model.background_exclude == (() if background is None else ("cafe-1.wav",))


@pytest.mark.parametrize("folds", [False, True])
def test_a_label_is_folded_in_where_the_recogniser_declares_it_can_be(folds):
    lock = threading.RLock()
    models = Models(
        acoustic=None,
        visual=declaring(folds_in=folds),
        samples={},
        decisions=DecisionPipeline(ParallelFusion()),
        bus=EventBus(lambda: 0.0),
        lock=lock,
        fresh_methods={},
        path=None,
        window_seconds=5.0,
        on_new_sound=lambda: None,
    )
    models.fold_in(Kept("image", np.zeros((4, 4, 3), np.uint8)), "cafe")
    assert models.retrain_needed == (not folds)
    assert models.visual.folded == (["cafe"] if folds else [])
