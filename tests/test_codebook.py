"""The codebook acoustic method: level and rate robustness, probabilities, model files, open set."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError

from servant_core.features.logmel import log_mel_frames, mel_filterbank
from servant_core.modelfile import load_model, save_model
from servant_core.recognisers import UNKNOWN, make_recogniser
from servant_core.recognisers.codebook import CodebookAcousticRecogniser

RATE = 22050


def noise_scene(rng: np.random.Generator, centre_hz: float, n: int) -> np.ndarray:
    """Windows of noise band-passed around `centre_hz` (a synthetic 'place')."""
    windows = []
    for _ in range(n):
        spectrum = np.fft.rfft(rng.standard_normal(RATE * 5))
        freqs = np.fft.rfftfreq(RATE * 5, 1 / RATE)
        spectrum *= np.exp(-0.5 * ((freqs - centre_hz) / (0.2 * centre_hz)) ** 2)
        windows.append(np.fft.irfft(spectrum, RATE * 5))
    out = np.array(windows, dtype=np.float32)
    return out / np.abs(out).max() * 0.5


@pytest.fixture(scope="module")
def trained() -> tuple[CodebookAcousticRecogniser, dict[str, np.ndarray]]:
    rng = np.random.default_rng(1)
    scenes = {"low": noise_scene(rng, 300, 8), "mid": noise_scene(rng, 1500, 8)}
    model = CodebookAcousticRecogniser(n_codewords=8, clusters_per_scene=2)
    X = model.featurize(np.concatenate(list(scenes.values())))
    model.fit(X, ["low"] * 8 + ["mid"] * 8)
    return model, scenes


def test_filterbank_stays_below_the_band_every_recording_has() -> None:
    bank = mel_filterbank(RATE, 1024, 40, 60.0, 10500.0)
    freqs = np.fft.rfftfreq(1024, 1 / RATE)
    assert bank[:, freqs > 10500].sum() == 0
    np.testing.assert_allclose(bank.sum(axis=1), 1.0)


def test_log_mel_frames_ignore_gain() -> None:
    window = np.random.default_rng(0).standard_normal(RATE).astype(np.float32) * 0.3
    np.testing.assert_allclose(log_mel_frames(window * 0.05), log_mel_frames(window), atol=1e-3)


def test_recognises_quieter_windows_of_a_trained_scene(trained) -> None:
    model, scenes = trained
    rng = np.random.default_rng(7)
    loud = noise_scene(rng, 1500, 3)
    quiet = model.featurize(loud * 0.02)
    same = model.codewords(quiet) == model.codewords(model.featurize(loud))
    assert same.mean() > 0.99  # rounding may flip a frame sitting on a tie, no more
    proba = model.predict_proba(quiet)
    assert np.all(np.argmax(proba, axis=1) == model.scenes_.index("mid"))


def test_probabilities_sum_to_one_and_favour_the_truth(trained) -> None:
    model, scenes = trained
    proba = model.predict_proba(model.featurize(scenes["low"][:2]))
    np.testing.assert_allclose(proba.sum(axis=1), 1.0)
    assert np.all(proba[:, model.scenes_.index("low")] > 0.5)


def test_far_window_is_unknown_and_fold_in_learns_it(trained) -> None:
    model, _ = trained
    model = CodebookAcousticRecogniser.from_state(*model.get_state())
    rng = np.random.default_rng(3)
    hiss = model.featurize(noise_scene(rng, 6000, 3))
    assert list(model.predict(hiss)) == [UNKNOWN] * 3
    model.fold_in(hiss, ["hiss"] * 3)
    assert "hiss" in model.scenes_
    assert list(model.predict(model.featurize(noise_scene(rng, 6000, 2)))) == ["hiss"] * 2


def test_model_file_round_trip(trained, tmp_path) -> None:
    model, scenes = trained
    path = save_model(tmp_path / "m.npz", {"acoustic": model})
    loaded = load_model(path)["acoustic"]
    X = model.featurize(scenes["mid"][:3])
    np.testing.assert_allclose(loaded.predict_proba(X), model.predict_proba(X))


def test_registered_and_unfitted_raises() -> None:
    model = make_recogniser("audio", "codebook")
    with pytest.raises(NotFittedError):
        model.predict(np.zeros((1, 10, 40), np.float32))
