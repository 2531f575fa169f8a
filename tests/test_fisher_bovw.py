"""Fisher vectors over dense SIFT: descriptors, the encoding, real pictures, files, fold-in."""

from __future__ import annotations

import copy
import re
import zipfile

import cv2
import numpy as np
import pytest
from sklearn.metrics import balanced_accuracy_score

from servant_core.errors import ServantError
from servant_core.features.dense_sift import (
    dense_root_sift,
    grid_centres,
    keypoint_positions,
    mirror_order,
    root_sift,
)
from servant_core.modelfile import load_model, save_model
from servant_core.recognisers import UNKNOWN, make_recogniser
from servant_core.recognisers.calibration import held_out_losses, least_regularised_within_error
from servant_core.recognisers.fisher_bovw import (
    FisherBovwVisualRecogniser,
    fisher_vectors,
    leading_directions,
    power_l2,
)
from tests.conftest import link_library
from tests.test_bovw import stripes


def test_the_grid_is_centred_and_every_patch_inside() -> None:
    centres = grid_centres(128, 4, 6)
    assert centres[0] - 8 >= 0 and centres[-1] + 8 <= 128
    assert abs((centres[0] + centres[-1]) - 128) <= 1
    assert (
        len(keypoint_positions(128, (4, 6), 6))
        == len(centres) ** 2 + len(grid_centres(128, 6, 6)) ** 2
    )
    with pytest.raises(ValueError):
        grid_centres(16, 6, 6)


def test_root_sift_is_the_square_root_of_the_l1_normalised_histogram() -> None:
    out = root_sift(np.array([[1.0, 3.0, 0.0], [0.0, 0.0, 0.0]]))
    np.testing.assert_allclose(out, [[0.5, np.sqrt(0.75), 0.0], [0.0, 0.0, 0.0]])
    # unit length: the Hellinger kernel of two histograms is their RootSIFTs' dot product
    np.testing.assert_allclose(np.linalg.norm(out[0]), 1.0)


def test_dense_sift_of_the_mirror_image_is_a_permutation() -> None:
    picture = stripes(np.random.default_rng(3), False, (30, 120, 200))
    picture[100:300, 50:200] = (200, 30, 30)  # something on the left, so the mirror differs
    d = dense_root_sift(picture)
    flipped = dense_root_sift(cv2.flip(picture, 1))
    patches, dims = mirror_order(128, (4, 6), 6)
    assert np.abs(d - flipped).mean() > 3 * np.abs(d[patches][:, dims] - flipped).mean()


def test_a_flat_picture_gives_zero_descriptors() -> None:
    flat = np.full((64, 64, 3), 90, np.uint8)
    assert not dense_root_sift(flat).any()


def test_fisher_vector_of_descriptors_at_the_means_has_no_mean_gradient() -> None:
    weights = np.array([0.5, 0.5], np.float32)
    means = np.array([[0.0, 0.0], [10.0, 10.0]], np.float32)
    variances = np.ones((2, 2), np.float32)
    x = np.array([[[0.0, 0.0], [10.0, 10.0]]], np.float32)  # one picture, a patch at each mean
    fv = fisher_vectors(x, weights, means, variances)
    assert fv.shape == (1, 2 * 2 * 2)
    np.testing.assert_allclose(fv[0, :4], 0.0, atol=1e-5)
    # σ-gradient: each component owns one patch with (x−μ)²/σ² − 1 = −1, over P √(2w) = 2·1
    np.testing.assert_allclose(fv[0, 4:], -0.5, atol=1e-5)
    # one patch off its mean by +1 in the first dimension: (1/σ)/(P √w) = 1/(2·√0.5)
    x[0, 0, 0] = 1.0
    fv = fisher_vectors(x, weights, means, variances)
    np.testing.assert_allclose(fv[0, 0], 1 / (2 * np.sqrt(0.5)), atol=1e-5)


def test_power_l2_normalisation() -> None:
    out = power_l2(np.array([[4.0, -9.0, 0.0]]))
    np.testing.assert_allclose(out, [[2 / np.sqrt(13), -3 / np.sqrt(13), 0.0]])


@pytest.mark.parametrize("shape", [(40, 300), (300, 40)])  # fewer rows than columns, and more
def test_leading_directions_are_the_svds(shape) -> None:
    rows = np.random.default_rng(0).normal(size=shape).astype(np.float32)
    rows -= rows.mean(axis=0)
    singular, vt = leading_directions(rows, 10, block=16)  # blocks that do not divide the sizes
    _, expected, expected_vt = np.linalg.svd(rows, full_matrices=False)
    np.testing.assert_allclose(singular, expected[:10], atol=1e-4)
    np.testing.assert_allclose(np.abs(np.sum(vt * expected_vt[:10], axis=1)), 1.0, atol=1e-6)


def small_model(**params) -> FisherBovwVisualRecogniser:
    return FisherBovwVisualRecogniser(
        pca_dim=8, n_components=4, head_dim=16, max_mixture_descriptors=4000, **params
    )


@pytest.fixture(scope="module")
def trained() -> tuple[FisherBovwVisualRecogniser, np.ndarray, np.ndarray]:
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


def test_a_picture_unlike_any_scene_is_unknown(trained) -> None:
    model, _, _ = trained
    noise = np.random.default_rng(4).integers(0, 255, (480, 640, 3)).astype(np.uint8)
    assert model.predict(model.featurize([noise]))[0] == UNKNOWN
    assert model.novelty(model.featurize([noise]))[0] > 1


def test_model_file_round_trip_gives_identical_probabilities(trained, tmp_path) -> None:
    model, X, _ = trained
    path = save_model(tmp_path / "v.npz", {"visual": model})
    loaded = load_model(path)["visual"]
    assert isinstance(loaded, FisherBovwVisualRecogniser)
    np.testing.assert_array_equal(loaded.predict_proba(X), model.predict_proba(X))
    assert list(loaded.predict(X)) == list(model.predict(X))


def test_a_corrupt_model_file_is_refused_in_one_line(trained, tmp_path) -> None:
    model, _, _ = trained
    path = save_model(tmp_path / "v.npz", {"visual": model})
    with zipfile.ZipFile(path) as archive:
        members = {i.filename: archive.read(i) for i in archive.infolist()}
    # the mixture's variances swapped for an array of the wrong shape
    broken = tmp_path / "broken.npz"
    arrays = {name[: -len(".npy")]: np.load(path)[name[: -len(".npy")]] for name in members}
    arrays["visual/variances"] = np.ones((3, 2), np.float32)
    np.savez(broken, **arrays)
    with pytest.raises(ServantError, match="damaged Servant model file") as raised:
        load_model(broken)
    assert "\n" not in str(raised.value)
    # a doctored grid that would take gigabytes a picture
    header = (
        str(arrays["header"])
        .replace('"step": 6', '"step": 1')
        .replace('"size": 128', '"size": 2048')
    )
    np.savez(broken, **{**arrays, "header": np.array(header)})
    with pytest.raises(ServantError, match="damaged Servant model file"):
        load_model(broken)
    # not a model at all
    foreign = tmp_path / "foreign.npz"
    foreign.write_bytes(b"PK\x03\x04 this is not a zip archive")
    with pytest.raises(ServantError, match="not a Servant model file"):
        load_model(foreign)


def test_the_model_file_stays_small(trained, tmp_path) -> None:
    model, _, _ = trained
    default = FisherBovwVisualRecogniser()
    # the default's largest arrays: the head's directions (head_dim × encoding) and its rows
    encoding = 2 * default.n_components * (default.pca_dim + 2) + 128
    assert default.head_dim * encoding * 4 < 10_000_000
    path = save_model(tmp_path / "v.npz", {"visual": model})
    assert path.stat().st_size < 1_000_000


def test_fold_in_learns_a_new_scene(trained) -> None:
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
        small_model().predict(np.zeros((1, 10), np.float16))


def test_beats_chance_on_real_pictures(shared_data, tmp_path) -> None:
    """Four scenes, 60 real pictures each by file order: the first 40 train, the rest test."""
    # imported here: the library module must not be the first of servant_core to load
    from servant_core.library import SceneLibrary, read_pictures

    scenes = ("cafe", "gym", "street", "vehicle")
    root = link_library(tmp_path / "lib", shared_data, {s: ([], 60) for s in scenes})
    images, kept = read_pictures(SceneLibrary.scan(root).pictures)
    labels = np.array([p.scene for p in kept])
    order = np.zeros(len(kept), bool)
    for scene in scenes:
        order[np.flatnonzero(labels == scene)[:40]] = True
    model = make_recogniser("image", "fisher-bovw", n_components=16, head_dim=64)
    X = model.featurize(images)
    model.fit(X[order], labels[order])
    predicted = np.asarray(model.scenes_)[np.argmax(model.predict_proba(X[~order]), axis=1)]
    # chance is 0.25; a recogniser that learned nothing stays near it
    assert balanced_accuracy_score(labels[~order], predicted) > 0.5


def test_held_out_losses_weigh_every_class_alike() -> None:
    log_proba = np.log(np.array([[0.5, 0.5], [0.9, 0.1], [0.8, 0.2], [0.25, 0.75]]))
    losses = held_out_losses(log_proba, np.array([0, 0, 0, 1]))
    # three rows of class 0 weigh 4 / (2·3) each, the one row of class 1 weighs 4 / (2·1)
    expected = [-np.log(0.5) * 2 / 3, -np.log(0.9) * 2 / 3, -np.log(0.8) * 2 / 3, -np.log(0.75) * 2]
    np.testing.assert_allclose(losses, expected)


def test_the_least_regularised_within_one_standard_error_is_chosen() -> None:
    losses = np.array([[0.70, 0.70, 0.70], [0.30, 0.50, 0.40], [0.45, 0.45, 0.45], [0.9, 1, 1.1]])
    # the best mean is 0.40 with a standard error of 0.1 / √3; 0.45 is within, 1.0 is not
    assert least_regularised_within_error(losses) == 2
    assert least_regularised_within_error(losses[:, :1]) == 1  # one row: no error, the best


def cafe_and_street(shared_data, draw: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    """Six café and six street pictures, drawn, and forty other pictures of each."""
    from servant_core.library import read_picture

    rng = np.random.default_rng(draw)
    taught, other, scenes = [], [], []
    for scene in ("cafe", "street"):
        paths = rng.permutation(sorted((shared_data / "images/dev" / scene).glob("*.jpg")))
        taught += list(paths[:6])
        other += list(paths[6:46])
        scenes += [scene] * 6
    pictures = [read_picture(p) for p in taught + other]
    return pictures[:12], np.array(scenes), np.repeat(["cafe", "street"], 40), pictures[12:]


@pytest.mark.slow
def test_a_picture_of_a_taught_place_reads_clearly_above_average(shared_data) -> None:
    """Taught six pictures a place (two places, as teach mode asks), other pictures of the café
    read clearly likelier the café than the average taught place, and street pictures clearly
    less (before, its regularisation was chosen for the ranking alone: every picture about
    1.0× average)."""
    own, street = [], []
    for draw in range(3):
        taught, scenes, truth, other = cafe_and_street(shared_data, draw)
        model = make_recogniser("image", "fisher-bovw")
        model.fit(model.featurize(taught), scenes)
        cafe = 2 * model.predict_proba(model.featurize(other))[:, model.scenes_.index("cafe")]
        own += list(cafe[truth == "cafe"])
        street += list(cafe[truth == "street"])
    assert np.median(own) >= 1.3 and np.median(street) <= 0.77, (np.median(own), np.median(street))


@pytest.mark.devices
@pytest.mark.slow
def test_servant_predict_shows_a_taught_picture_clearly_above_average(shared_data, tmp_path):
    """What the user reads: a model trained as `servant train` trains it, on a library of two
    places with six pictures each, and `servant predict --image` on one of the café's own
    pictures."""
    from tests.conftest import servant
    from tests.test_cli_recognition import TWO_PLACES

    library = link_library(tmp_path / "lib", shared_data, TWO_PLACES)
    model = tmp_path / "model.npz"
    trained = servant("train", str(library), "-o", str(model))
    assert trained.returncode == 0, trained.stderr
    taught = sorted((library / "cafe").glob("*.jpg"))
    assert len(taught) == 6
    result = servant("predict", str(model), "--image", *map(str, taught[:3]))
    assert result.returncode == 0, result.stderr
    seen = [line for line in result.stdout.splitlines() if line.startswith("Visual")]
    shown = [re.search(r"cafe \(confidence ([\d.]+)× average\)", line) for line in seen]
    figures = [float(found[1]) for found in shown if found]
    assert len(figures) == 3 and min(figures) > 1.3, result.stdout
