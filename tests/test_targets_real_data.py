"""The methods beyond the paper on a small slice of the real data (the full figures are in the
README, from `servant eval` and bench/open_set.py): they must beat chance by far where the
paper's method does not, through the same evaluation code the CLI uses."""

from __future__ import annotations

import pytest

from servant_core.evaluate import evaluate_audio, evaluate_fusion, evaluate_image
from servant_core.library import SceneLibrary
from tests.conftest import link_library

pytestmark = pytest.mark.slow

RECORDINGS = {
    "cafe": (["moodist-crowded-bar.mp3"], 40),
    "street": (["moodist-traffic.mp3"], 40),
    "vehicle": (["moodist-airplane.mp3"], 40),
    "office": (["moodist-office.mp3"], 40),
}


@pytest.fixture(scope="module")
def library(shared_data, tmp_path_factory) -> SceneLibrary:
    root = link_library(tmp_path_factory.mktemp("slice"), shared_data, RECORDINGS)
    return SceneLibrary.scan(root)


def test_codebook_temporal_on_four_places(library) -> None:
    result = evaluate_audio(library, "codebook", "temporal")
    assert result["balanced_accuracy"] >= 0.9
    assert 0 < result["log_loss"] < 1.0


def test_bovw_beats_dominant_colours_on_pictures(library) -> None:
    bovw = evaluate_image(library, method="bovw")
    paper = evaluate_image(library, method="paper")
    assert bovw["balanced_accuracy"] > 0.45  # chance is 0.25
    assert bovw["balanced_accuracy"] > paper["balanced_accuracy"]


def test_parallel_fusion_is_right_when_it_decides(library) -> None:
    result = evaluate_fusion(library, "codebook", "bovw", "parallel")
    assert result["decision_rate"] >= 0.8
    assert result["precision"] >= 0.95
