"""Open set: the per-scene centroids say "unknown" far from every scene, and fold in labels."""

from __future__ import annotations

import numpy as np
import pytest

from servant_core.recognisers import UNKNOWN
from servant_core.recognisers.centroids import SceneCentroids


@pytest.fixture()
def two_scenes() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    D = np.vstack([rng.normal(0, 1, (40, 3)), rng.normal(10, 1, (40, 3))])
    return D, np.array(["a"] * 40 + ["b"] * 40)


def fit(D, y, quantile=0.95, margin=1.5, shrinkage=0.0) -> SceneCentroids:
    return SceneCentroids.fit(D, y, 2, quantile, margin, 0, shrinkage)


def test_threshold_is_the_quantile_of_training_distances_in_spreads(two_scenes) -> None:
    D, y = two_scenes
    head = fit(D, y, quantile=1.0, margin=1.0)
    # the farthest training row sits exactly on the threshold: every training row is known
    assert np.max(head.nearest_scaled(D)) == pytest.approx(head.reject_distance)
    assert UNKNOWN not in set(head.predict(D))


def test_far_rows_are_unknown_near_rows_are_named(two_scenes) -> None:
    D, y = two_scenes
    head = fit(D, y)
    far = np.array([[5.0, 5.0, 5.0], [-20.0, 0.0, 0.0]])
    near = np.array([[0.1, -0.2, 0.0], [10.0, 9.5, 10.2]])
    assert list(head.predict(far)) == [UNKNOWN, UNKNOWN]
    assert list(head.predict(near)) == ["a", "b"]
    np.testing.assert_allclose(head.proba(far).sum(axis=1), 1.0)


def test_fold_in_is_a_running_mean_and_variance(two_scenes) -> None:
    D, y = two_scenes
    head = fit(D, y)
    new = np.random.default_rng(1).normal(0.5, 1, (5, 3))
    c = int(np.argmin(np.linalg.norm(head.centres - new[0], axis=1)))
    members = D[np.argmin(head.distances(D), axis=1) == c]  # the cluster's training rows
    n0 = head.counts[c]
    assert n0 == len(members)
    head.fold_in(new[:1], ["a"])
    expected = np.vstack([members, new[:1]])
    np.testing.assert_allclose(head.centres[c], expected.mean(axis=0))
    rms = np.sqrt(np.mean(np.sum((expected - expected.mean(axis=0)) ** 2, axis=1)))
    assert head.spreads[c] == pytest.approx(rms)


def test_fold_in_a_new_scene_makes_it_recognisable(two_scenes) -> None:
    D, y = two_scenes
    head = fit(D, y)
    place = np.array([[-20.0, 0.0, 0.0]])
    assert head.predict(place)[0] == UNKNOWN
    head.fold_in(place, ["garden"])
    assert head.scenes == ["a", "b", "garden"]
    assert head.predict(place + 0.1)[0] == "garden"
    header, arrays = head.state()
    again = SceneCentroids.from_state(header, arrays)
    assert again.predict(place + 0.1)[0] == "garden"


def test_shrinkage_makes_spreads_equal(two_scenes) -> None:
    D, y = two_scenes
    D = D.copy()
    D[y == "b"] *= 3  # scene b is broader
    own = fit(D, y)
    pooled = fit(D, y, shrinkage=1.0)
    assert np.ptp(own.spreads) > 0.5
    np.testing.assert_allclose(pooled.spreads, np.median(own.spreads))
