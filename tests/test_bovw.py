"""The bag-of-visual-words method: descriptors, pyramid histograms, fit/predict, model files."""

from __future__ import annotations

import numpy as np
import pytest

from servant_core.features.descriptors import dense_descriptors, square_thumbnail
from servant_core.modelfile import load_model, save_model
from servant_core.recognisers.bovw import BovwVisualRecogniser, pyramid_histograms


def stripes(rng: np.random.Generator, vertical: bool, colour: tuple[int, int, int]) -> np.ndarray:
    """A 480×640 picture of noisy stripes of one orientation and colour (a synthetic place)."""
    image = np.zeros((480, 640, 3), np.uint8)
    image[:] = colour
    for k in range(0, 640 if vertical else 480, 40):
        if vertical:
            image[:, k : k + 20] //= 3
        else:
            image[k : k + 20, :] //= 3
    noise = rng.integers(-20, 20, image.shape)
    return np.clip(image.astype(int) + noise, 0, 255).astype(np.uint8)


def test_camera_frame_and_library_picture_give_the_same_grid() -> None:
    frame = np.zeros((480, 640, 3), np.uint8)
    assert square_thumbnail(frame).shape == (128, 128, 3)
    assert dense_descriptors(frame).shape == dense_descriptors(frame[:128, :128]).shape == (225, 39)


def test_orientation_blocks_are_unit_length_and_see_direction() -> None:
    image = stripes(np.random.default_rng(0), True, (200, 200, 200))
    d = dense_descriptors(image)
    np.testing.assert_allclose(np.linalg.norm(d[:, :36], axis=1), 1.0, atol=1e-3)
    bins = d[:, :36].reshape(-1, 4, 9).sum(axis=(0, 1))
    assert np.argmax(bins) in (0, 8)  # vertical stripes: horizontal gradients (angle ~0 or pi)


def test_pyramid_histograms_count_words_per_quarter() -> None:
    words = np.zeros((1, 16), dtype=np.intp)
    words[0, :2] = 1  # two blocks of the top-left quarter use word 1
    h = pyramid_histograms(words, 2)
    np.testing.assert_allclose(h[0, :2], [14 / 16, 2 / 16])
    np.testing.assert_allclose(h[0, 2:4], [2 / 4, 2 / 4])
    np.testing.assert_allclose(h[0, 4:], [1, 0, 1, 0, 1, 0])


@pytest.fixture(scope="module")
def trained() -> tuple[BovwVisualRecogniser, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(2)
    pictures = [stripes(rng, True, (40, 160, 40)) for _ in range(6)]
    pictures += [stripes(rng, False, (160, 40, 160)) for _ in range(6)]
    # Twelve pictures are too few for the discriminant step (it has more dimensions than rows);
    # tests/test_targets_real_data.py runs the default method on real pictures.
    model = BovwVisualRecogniser(
        n_words=16, n_colour_words=4, clusters_per_scene=1, discriminant=False
    )
    X = model.featurize(pictures)
    y = np.array(["park"] * 6 + ["club"] * 6)
    return model.fit(X, y), X, y


def test_recognises_new_pictures_of_each_scene(trained) -> None:
    model, _, _ = trained
    rng = np.random.default_rng(9)
    new = model.featurize([stripes(rng, True, (40, 160, 40)), stripes(rng, False, (160, 40, 160))])
    assert list(model.predict(new)) == ["park", "club"]
    np.testing.assert_allclose(model.predict_proba(new).sum(axis=1), 1.0)


def test_model_file_round_trip(trained, tmp_path) -> None:
    model, X, _ = trained
    loaded = load_model(save_model(tmp_path / "v.npz", {"visual": model}))["visual"]
    np.testing.assert_allclose(loaded.predict_proba(X), model.predict_proba(X))
