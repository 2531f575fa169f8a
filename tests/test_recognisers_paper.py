import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from servant_core.errors import ServantError
from servant_core.recognisers import UNKNOWN, make_recogniser
from servant_core.recognisers.base import label_clusters, scene_probabilities
from servant_core.recognisers.paper import PaperAcousticRecogniser, PaperVisualRecogniser
from tests.conftest import tone


def test_label_clusters_by_majority_reports_ties_and_orphans():
    clusters = np.array([0, 0, 0, 1, 1, 2])
    scenes = ["cafe", "cafe", "gym", "gym", "street", "cafe"]
    labels = label_clusters(clusters, scenes, 4)
    assert labels.cluster_scene == ["cafe", None, "cafe", None]
    assert labels.tied_clusters == [1]
    assert labels.empty_clusters == [3]
    assert labels.unowned_scenes == ["gym", "street"]
    assert any("gym" in w for w in labels.warnings())


def test_probabilities_sum_to_one_and_favour_the_near_scene():
    distances = np.array([[1.0, 5.0], [50.0, 52.0]])
    probs = scene_probabilities(distances, np.array([1.0, 1.0]), ["a", "b"], ["a", "b"])
    assert np.allclose(probs.sum(axis=1), 1.0)
    assert probs[0, 0] > 0.99
    assert np.all(np.isfinite(probs))


def test_acoustic_recogniser_separates_two_tones_and_follows_sklearn_conventions():
    rate = 4000
    windows = np.stack(
        [tone(f, 1.0, rate, a) for f, a in [(300, 0.5), (300, 0.45), (1500, 0.5), (1500, 0.45)]]
    )
    model = PaperAcousticRecogniser(rate=rate, window_seconds=1.0, random_state=0)
    with pytest.raises(NotFittedError):
        model.predict(model.featurize(windows))
    X = model.featurize(windows)
    assert model.fit(X, ["low", "low", "high", "high"]) is model
    assert model.predict(X).tolist() == ["low", "low", "high", "high"]
    assert model.scenes_ == ["high", "low"]
    again = PaperAcousticRecogniser(rate=rate, window_seconds=1.0, random_state=0).fit(
        X, ["low", "low", "high", "high"]
    )
    # reproducible by random_state (to float rounding: K-Means centres X in place and restores it)
    assert np.allclose(again.centres_, model.centres_, rtol=1e-5)
    # eq. 1 against the nearest centroid, computed by hand
    nearest = np.min(np.linalg.norm(X[:, None, :] - model.centres_[None], axis=2), axis=1)
    assert np.allclose(model.confidence(X), 100 - nearest / 10000, rtol=1e-4)


def test_one_scene_is_refused_clearly():
    model = PaperVisualRecogniser()
    with pytest.raises(ServantError, match="at least two scenes"):
        model.fit(np.zeros((4, 9), np.float32), ["cafe"] * 4)


def test_visual_recogniser_on_coloured_pictures():
    rng = np.random.default_rng(0)

    def picture(bgr):
        image = np.full((60, 80, 3), bgr, np.uint8)
        return np.clip(image + rng.normal(0, 6, image.shape), 0, 255).astype(np.uint8)

    brown = [picture((40, 80, 140)) for _ in range(4)]  # a café's browns (BGR)
    wood = [picture((90, 170, 220)) for _ in range(4)]  # a gym floor's light wood
    model = make_recogniser("image", "paper", n_colours=2)
    X = model.featurize(brown + wood)
    model.fit(X, ["cafe"] * 4 + ["gym"] * 4)
    test = model.featurize([picture((40, 80, 140)), picture((90, 170, 220))])
    assert model.predict(test).tolist() == ["cafe", "gym"]
    assert np.all(model.confidence(test) > 80)  # within a few RGB units of the centroid
    assert model.matched_palette(test).shape == (2, 2, 3)


def test_a_tied_cluster_predicts_unknown():
    model = PaperVisualRecogniser(n_colours=1, n_init=1)
    X = np.array([[0, 0, 0], [0, 0, 0], [200, 200, 200], [200, 200, 200]], np.float32)
    model.fit(X, ["a", "b", "a", "b"])  # each cluster holds one "a" and one "b": ties
    assert set(model.predict(X).tolist()) == {UNKNOWN}
    assert sorted(model.labels_.unowned_scenes) == ["a", "b"]


def test_unknown_method_is_a_clear_error():
    with pytest.raises(ServantError, match="no audio method named 'nope'"):
        make_recogniser("audio", "nope")


def test_cluster_spreads_are_rms_distances_to_the_own_centre():
    from servant_core.recognisers.base import cluster_spreads

    X = np.array([[0, 0], [2, 0], [10, 0], [10, 4], [50, 50]], np.float32)
    centres = np.array([[1, 0], [10, 2], [50, 50]], np.float32)
    spreads = cluster_spreads(X, np.array([0, 0, 1, 1, 2]), centres)
    # cluster 2 has one member: it takes the median of the others' spreads
    assert spreads.tolist() == pytest.approx([1.0, 2.0, 1.5])
