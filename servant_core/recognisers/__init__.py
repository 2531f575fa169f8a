"""Recognisers by sense and method name; `paper` is the paper's, the others go beyond it."""

from __future__ import annotations

import importlib
from typing import Any, cast

from servant_core.choices import FRESH_AUDIO_METHOD, FRESH_IMAGE_METHOD
from servant_core.errors import ServantError
from servant_core.recognisers.base import UNKNOWN, AcousticRecogniser, Recogniser
from servant_core.recognisers.birdnet import BirdnetAcousticRecogniser
from servant_core.recognisers.bovw import BovwVisualRecogniser
from servant_core.recognisers.codebook import CodebookAcousticRecogniser
from servant_core.recognisers.effnet import EffnetVisualRecogniser
from servant_core.recognisers.fisher_bovw import FisherBovwVisualRecogniser
from servant_core.recognisers.kmeans_encoder import KMeansEncoderAcousticRecogniser
from servant_core.recognisers.paper import PaperAcousticRecogniser, PaperVisualRecogniser
from servant_core.recognisers.softbovw import SoftBovwVisualRecogniser
from servant_core.senses import SAMPLE_METHOD, SAMPLE_SENSES

ACOUSTIC_METHODS: dict[str, type[Recogniser]] = {
    "paper": PaperAcousticRecogniser,
    "codebook": CodebookAcousticRecogniser,
    "kmeans-encoder": KMeansEncoderAcousticRecogniser,
    "birdnet": BirdnetAcousticRecogniser,
}
VISUAL_METHODS: dict[str, type[Recogniser]] = {
    "paper": PaperVisualRecogniser,
    "bovw": BovwVisualRecogniser,
    "softbovw": SoftBovwVisualRecogniser,
    "fisher-bovw": FisherBovwVisualRecogniser,
    "effnet": EffnetVisualRecogniser,
}


def _entry(path: str) -> type[Recogniser]:
    module, _, name = path.partition(":")
    cls: type[Recogniser] = getattr(importlib.import_module(module), name)
    return cls


# each sense's methods by name: a sample sense's recogniser comes from its line in `SENSES`
SENSE_METHODS: dict[str, dict[str, type[Recogniser]]] = {
    "audio": ACOUSTIC_METHODS,
    "image": VISUAL_METHODS,
    **{
        name: {SAMPLE_METHOD: _entry(sense.recogniser)}
        for name, sense in SAMPLE_SENSES.items()
        if sense.recogniser
    },
}


def methods_for(sense: str) -> dict[str, type[Recogniser]]:
    if sense not in SENSE_METHODS:
        raise ValueError(f"unknown sense {sense!r}")
    return SENSE_METHODS[sense]


def make_audio_recogniser(method: str, **params: Any) -> AcousticRecogniser:
    return cast(AcousticRecogniser, make_recogniser("audio", method, **params))


# What a retrain fits for a sense that has no recogniser yet, and what `servant train` and the
# demo use (`choices`).
FRESH_METHODS = {
    "audio": FRESH_AUDIO_METHOD,
    "image": FRESH_IMAGE_METHOD,
    **{name: SAMPLE_METHOD for name in SAMPLE_SENSES},
}


def make_recogniser(sense: str, method: str, **params: Any) -> Recogniser:
    methods = methods_for(sense)
    if method not in methods:
        raise ServantError(
            f"no {sense} method named {method!r}; choose one of {', '.join(sorted(methods))}"
        )
    return methods[method](**params)


__all__ = [
    "ACOUSTIC_METHODS",
    "FRESH_METHODS",
    "AcousticRecogniser",
    "UNKNOWN",
    "VISUAL_METHODS",
    "Recogniser",
    "SENSE_METHODS",
    "make_audio_recogniser",
    "make_recogniser",
    "methods_for",
]
