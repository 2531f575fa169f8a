"""Recognisers by sense and method name; `paper` is the paper's, the others go beyond it."""

from __future__ import annotations

from typing import Any

from servant_core.errors import ServantError
from servant_core.recognisers.base import UNKNOWN, Recogniser
from servant_core.recognisers.bovw import BovwVisualRecogniser
from servant_core.recognisers.codebook import CodebookAcousticRecogniser
from servant_core.recognisers.paper import PaperAcousticRecogniser, PaperVisualRecogniser

ACOUSTIC_METHODS: dict[str, type] = {
    "paper": PaperAcousticRecogniser,
    "codebook": CodebookAcousticRecogniser,
}
VISUAL_METHODS: dict[str, type] = {"paper": PaperVisualRecogniser, "bovw": BovwVisualRecogniser}


def methods_for(sense: str) -> dict[str, type]:
    if sense == "audio":
        return ACOUSTIC_METHODS
    if sense == "image":
        return VISUAL_METHODS
    raise ValueError(f"unknown sense {sense!r}")


def make_recogniser(sense: str, method: str, **params: Any) -> Recogniser:
    methods = methods_for(sense)
    if method not in methods:
        raise ServantError(
            f"no {sense} method named {method!r}; choose one of {', '.join(sorted(methods))}"
        )
    return methods[method](**params)


__all__ = [
    "ACOUSTIC_METHODS",
    "UNKNOWN",
    "VISUAL_METHODS",
    "Recogniser",
    "make_recogniser",
    "methods_for",
]
