"""The soft-encoded bag of words: triangle activations, regions, fit/predict, files, fold-in."""

from __future__ import annotations

import numpy as np
import pytest

from servant_core.modelfile import load_model, save_model
from servant_core.recognisers import UNKNOWN
from servant_core.recognisers.softbovw import (
    SoftBovwVisualRecogniser,
    mirrored,
    one_standard_error_choice,
    pooled,
    region_masks,
    triangle_activations,
)
from tests.test_bovw import stripes


def test_triangle_activations_fire_for_near_words_only() -> None:
    words = np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]])
    # distances from the origin: 0, 3, 4; mean 7/3 → activations 7/3, 0, 0
    out = triangle_activations(np.array([[0.0, 0.0]]), words)
    np.testing.assert_allclose(out, [[7 / 3, 0.0, 0.0]])
    # from (1, 0): distances 1, 2, √17; mean (3 + √17)/3
    out = triangle_activations(np.array([[1.0, 0.0]]), words)
    mean = (3 + np.sqrt(17)) / 3
    np.testing.assert_allclose(out, [[mean - 1, mean - 2, 0.0]])


def test_regions_cut_the_grid_and_pooling_averages_them() -> None:
    masks = region_masks(16, (1, 2))
    assert masks.shape == (5, 16)
    assert masks[0].all() and (masks[1:].sum(axis=0) == 1).all()
    assert masks[1].reshape(4, 4)[:2, :2].all()  # the first quarter is the top left one
    activations = np.zeros((1, 16, 2))
    activations[0, 0, 1] = 4.0  # one block of the top-left quarter uses word 1
    np.testing.assert_allclose(pooled(activations, masks)[0], [0, 0.25, 0, 1, 0, 0, 0, 0, 0, 0])


def test_the_simplest_setting_within_one_standard_error_wins() -> None:
    # best: setting 2, mean 0.6, folds 0.5/0.7 → standard error 0.1414/√2 = 0.1
    scores = np.array([[0.40, 0.42], [0.52, 0.50], [0.50, 0.70]])
    assert one_standard_error_choice(scores) == 1  # 0.51 ≥ 0.5; 0.41 is not
    assert one_standard_error_choice(np.array([[0.3, 0.3], [0.6, 0.6]])) == 1


def small_model(**params) -> SoftBovwVisualRecogniser:
    return SoftBovwVisualRecogniser(n_words=8, n_colour_words=4, **params)


@pytest.fixture(scope="module")
def trained() -> tuple[SoftBovwVisualRecogniser, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(2)
    pictures = [stripes(rng, True, (40, 160, 40)) for _ in range(8)]
    pictures += [stripes(rng, False, (160, 40, 160)) for _ in range(8)]
    model = small_model()
    X = model.featurize(pictures)
    y = np.array(["park"] * 8 + ["club"] * 8)
    return model.fit(X, y), X, y


def test_recognises_new_pictures_of_each_scene(trained) -> None:
    model, _, _ = trained
    rng = np.random.default_rng(9)
    new = model.featurize([stripes(rng, True, (40, 160, 40)), stripes(rng, False, (160, 40, 160))])
    assert list(model.predict(new)) == ["park", "club"]
    proba = model.predict_proba(new)
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    assert proba[0, model.scenes_.index("park")] > 0.5


def test_regularisation_is_chosen_inside_the_training_pictures(trained) -> None:
    model, _, _ = trained
    assert model.C is None and model.C_ > 0


def test_a_picture_unlike_any_scene_is_unknown(trained) -> None:
    model, _, _ = trained
    noise = np.random.default_rng(4).integers(0, 255, (480, 640, 3)).astype(np.uint8)
    assert model.predict(model.featurize([noise]))[0] == UNKNOWN


def test_model_file_round_trip(trained, tmp_path) -> None:
    model, X, _ = trained
    loaded = load_model(save_model(tmp_path / "v.npz", {"visual": model}))["visual"]
    assert isinstance(loaded, SoftBovwVisualRecogniser)
    np.testing.assert_allclose(loaded.predict_proba(X), model.predict_proba(X))
    assert list(loaded.predict(X)) == list(model.predict(X))


def test_fold_in_learns_a_new_scene(trained) -> None:
    import copy

    model = copy.deepcopy(trained[0])
    rng = np.random.default_rng(5)
    yellow = model.featurize([stripes(rng, True, (20, 200, 230)) for _ in range(4)])
    model.fold_in(yellow, ["beach"] * 4)
    assert "beach" in model.scenes_
    again = model.featurize([stripes(rng, True, (20, 200, 230))])
    assert model.predict(again)[0] == "beach"


def test_predict_before_fit_is_refused() -> None:
    from sklearn.exceptions import NotFittedError

    with pytest.raises(NotFittedError):
        small_model().predict(np.zeros((1, 10), np.float32))


def test_mirrored_blocks_are_those_of_the_mirror_image() -> None:
    import cv2

    from servant_core.features.descriptors import block_descriptors

    picture = stripes(np.random.default_rng(3), False, (30, 120, 200))
    picture[100:300, 50:200] = (200, 30, 30)  # something on the left, so the mirror differs
    g, c = (a[None] for a in block_descriptors(picture))
    fg, fc = (a[None] for a in block_descriptors(cv2.flip(picture, 1)))
    mg, mc = mirrored(g, c)
    assert np.abs(g - fg).mean() > 5 * np.abs(mg - fg).mean()
    np.testing.assert_allclose(mc, fc, atol=1e-3)
    # only gradients lying exactly on a bin edge (θ = 0) land in another bin
    assert np.abs(mg - fg).mean() < 0.02
    np.testing.assert_array_equal(mirrored(mg, mc)[0], g)
