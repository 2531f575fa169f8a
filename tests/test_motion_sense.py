"""Motion and ambient senses: features on exact signals, the synthesised scenes, the per-scene
K-Means recognisers (fit, predict, open set, calibration), model files and the evaluation."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest

from servant_core.demo.motion_synth import (
    MOTION_KINDS,
    synth_ambient,
    synth_motion,
    write_sensor_library,
)
from servant_core.errors import ServantError
from servant_core.evaluate_motion import (
    cut_sample_windows,
    evaluate_library,
    evaluate_synthesised,
    score,
)
from servant_core.features.ambient import ambient_features, trend_per_minute
from servant_core.features.motion import (
    MOTION_FEATURES,
    band_energies,
    dominant_frequency,
    motion_features,
)
from servant_core.modelfile import load_model, save_model
from servant_core.recognisers import UNKNOWN, make_recogniser, methods_for
from servant_core.recognisers.sensor_centroids import AmbientRecogniser, MotionRecogniser

RATE = 50
T = np.arange(250) / RATE  # a 5 s window


def still(extra: np.ndarray | None = None) -> np.ndarray:
    window = np.zeros((len(T), 6))
    window[:, 2] = 9.81
    if extra is not None:
        window[:, 2] += extra
    return window


def test_a_sine_puts_its_energy_in_its_band():
    for freq, band in ((1.8, 1), (14.0, 3), (0.6, 0)):
        energies = band_energies(2.0 * np.sin(2 * np.pi * freq * T), RATE)
        assert energies[band] == pytest.approx(2.0, rel=0.1)  # A²/2
        assert energies.sum() - energies[band] < 0.05 * energies[band]
    assert dominant_frequency(np.sin(2 * np.pi * 1.8 * T), RATE, (0.5, 4.0)) == pytest.approx(1.8)


def test_bands_above_the_nyquist_frequency_are_empty():
    energies = band_energies(np.sin(2 * np.pi * 3.5 * np.arange(80) / 10), 10)
    assert energies[3] == 0.0 and energies[2] > 0


def test_motion_features_tell_still_from_walking_from_vibration():
    names = dict(zip(MOTION_FEATURES, range(len(MOTION_FEATURES)), strict=True))
    quiet = motion_features(still(), RATE)
    walking = motion_features(still(2.5 * np.sin(2 * np.pi * 1.8 * T)), RATE)
    shaking = motion_features(still(0.4 * np.sin(2 * np.pi * 14 * T)), RATE)
    assert quiet[names["acc_mean"]] == pytest.approx(9.81)
    assert quiet[names["acc_log_std"]] == pytest.approx(-3.0)  # the floor: no motion at all
    assert walking[names["cadence_hz"]] == pytest.approx(1.8)
    assert walking[names["band_1_3_log"]] > shaking[names["band_1_3_log"]] + 3
    assert shaking[names["band_8_20_log"]] > walking[names["band_8_20_log"]] + 3
    # turning the sensor (where gravity points) leaves the features unchanged
    turned = still(2.5 * np.sin(2 * np.pi * 1.8 * T))[:, [2, 0, 1, 3, 4, 5]]
    assert motion_features(turned, RATE) == pytest.approx(walking)
    with pytest.raises(ValueError):
        motion_features(np.zeros((250, 3)), RATE)


def test_ambient_features_use_log_light_and_the_pressure_trend_not_its_level():
    n = 10
    window = np.stack([np.full(n, 1000.0), np.full(n, 21.0), 1000 + 0.1 * np.arange(n)], axis=1)
    features = ambient_features(window, 2)
    assert features[:4] == pytest.approx([3.0, 0.0, 21.0, 0.0])
    assert features[4] == pytest.approx(12.0)  # 0.1 hPa every half second
    higher = window.copy()
    higher[:, 2] += 25  # another day's weather
    assert ambient_features(higher, 2) == pytest.approx(features)
    assert trend_per_minute(np.array([5.0]), 2) == 0.0
    window[:, 0] = 0  # darkness stays finite
    assert np.isfinite(ambient_features(window, 2)).all()


def test_synthesis_is_seeded_and_walking_has_its_cadence():
    a = synth_motion("street", np.random.default_rng(4))
    assert a.shape == (250, 6) and a.dtype == np.float32
    assert np.array_equal(a, synth_motion("street", np.random.default_rng(4)))
    assert not np.array_equal(a, synth_motion("street", np.random.default_rng(5)))
    cadence = motion_features(a, RATE)[MOTION_FEATURES.index("cadence_hz")]
    assert 1.4 <= cadence <= 2.2
    for kind in MOTION_KINDS:
        assert np.isfinite(synth_motion(kind, np.random.default_rng(0))).all()
    assert synth_ambient("street", np.random.default_rng(0))[:, 0].min() > 2000


def training(sense: str, per_scene: int = 24, seed: int = 0):
    make = synth_motion if sense == "motion" else synth_ambient
    scenes = ("coffee", "gym", "street")
    windows = [
        make(s, np.random.default_rng([seed, i, j]))
        for i, s in enumerate(scenes)
        for j in range(per_scene)
    ]
    return windows, [s for s in scenes for _ in range(per_scene)]


@pytest.mark.parametrize("sense", ["motion", "ambient"])
def test_the_recogniser_learns_the_scenes_and_calls_a_new_place_unknown(sense):
    model = make_recogniser(sense, "kmeans")
    assert type(model) is {"motion": MotionRecogniser, "ambient": AmbientRecogniser}[sense]
    windows, scenes = training(sense)
    assert model.fit(model.featurize(windows), scenes) is model
    test, truth = training(sense, 10, seed=1)
    X = model.featurize(test)
    predicted = model.predict(X)
    assert score(truth, predicted).balanced_accuracy >= 0.9
    proba = model.predict_proba(X)
    assert proba.shape == (30, 3) and np.allclose(proba.sum(axis=1), 1)
    assert model.confidence(X) == pytest.approx(100 * proba.max(axis=1))
    # a place unlike any taught: a vehicle's vibration, a dark freezing cellar
    if sense == "motion":
        strange = [synth_motion("vehicle", np.random.default_rng(i)) for i in range(5)]
    else:
        strange = [np.tile([2.0, -5.0, 1013.0], (10, 1)) for _ in range(5)]
    assert np.all(model.predict(model.featurize(strange)) == UNKNOWN)


def test_probabilities_are_calibrated_on_held_out_rows():
    windows, scenes = training("ambient")
    model = AmbientRecogniser().fit(AmbientRecogniser().featurize(windows), scenes)
    assert 0.5 <= model.spread_factor_ <= 16
    few = AmbientRecogniser().fit(AmbientRecogniser().featurize(windows[::12]), scenes[::12])
    assert few.spread_factor_ == 1.0  # two rows a scene: nothing to hold out


def test_motion_and_ambient_round_trip_through_a_model_file(tmp_path):
    models = {}
    for sense in ("motion", "ambient"):
        windows, scenes = training(sense)
        model = make_recogniser(sense, "kmeans", random_state=3)
        models[sense] = model.fit(model.featurize(windows), scenes)
    path = save_model(tmp_path / "model.npz", models)
    loaded = load_model(path)
    for sense, model in models.items():
        again = loaded[sense]
        assert type(again) is type(model) and again.params() == model.params()
        test, _ = training(sense, 4, seed=2)
        X = model.featurize(test)
        assert np.array_equal(again.predict(X), model.predict(X))
        assert again.predict_proba(X) == pytest.approx(model.predict_proba(X))


@pytest.mark.parametrize(
    ("field", "value", "said"),
    [("rate", 48000, "rate"), ("rate", 0, "rate"), ("window_seconds", 1e6, "window_seconds")],
)
def test_a_doctored_sensor_model_is_refused(tmp_path, field, value, said):
    windows, scenes = training("motion", 10)
    model = MotionRecogniser()
    path = save_model(tmp_path / "m.npz", {"motion": model.fit(model.featurize(windows), scenes)})
    with np.load(path) as stored:
        arrays = {k: stored[k] for k in stored.files}
    header = json.loads(str(arrays["header"]))
    header["recognisers"]["motion"]["params"][field] = value
    arrays["header"] = np.array(json.dumps(header))
    doctored = tmp_path / "doctored.npz"
    np.savez(doctored, **arrays)
    with pytest.raises(ServantError, match=said):
        load_model(doctored)


def test_a_sensor_model_with_the_wrong_sense_is_refused(tmp_path):
    windows, scenes = training("ambient", 10)
    model = AmbientRecogniser()
    path = save_model(tmp_path / "a.npz", {"motion": model.fit(model.featurize(windows), scenes)})
    with pytest.raises(ServantError, match="damaged"):
        load_model(path)
    assert zipfile.is_zipfile(path)


def test_sensor_methods_are_registered():
    assert set(methods_for("motion")) == {"kmeans"} and set(methods_for("ambient")) == {"kmeans"}
    with pytest.raises(ServantError, match="choose one of kmeans"):
        make_recogniser("motion", "bovw")


def test_evaluation_on_synthesised_windows_and_on_a_library_of_csv_logs(tmp_path):
    result = evaluate_synthesised("motion", seed=0, windows_per_scene=8)
    assert result.n_windows == 32 and 0.7 <= result.balanced_accuracy <= 1.0
    root = write_sensor_library(tmp_path / "lib", seed=0, windows_per_scene=4)
    (root / "gym" / "broken.imu.csv").write_text("time,ax\n")
    found, skipped = evaluate_library(root, "motion", folds=2)
    assert found.n_windows == 12 and found.balanced_accuracy >= 0.6
    assert len(skipped) == 1 and "broken.imu.csv" in skipped[0]
    with pytest.raises(ServantError, match="no .ambient.csv files"):
        evaluate_library(tmp_path, "ambient")


def test_score_counts_unknown_as_a_miss_and_windows_are_cut_whole():
    result = score(["a", "a", "b", "b"], ["a", UNKNOWN, "b", "a"])
    assert result.balanced_accuracy == pytest.approx(0.5)
    assert result.decision_rate == pytest.approx(0.75)
    assert result.precision == pytest.approx(2 / 3)
    assert [len(w) for w in cut_sample_windows(np.zeros((620, 6)), 50)] == [250, 250]
