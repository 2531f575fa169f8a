"""The kmeans-encoder acoustic method: its maths, probabilities, few examples, open set, fold-in,
model files; and (slow) its key figure on the real data."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.exceptions import NotFittedError
from sklearn.linear_model import LogisticRegression

from servant_core.modelfile import load_model, save_model
from servant_core.recognisers import UNKNOWN, make_recogniser
from servant_core.recognisers.kmeans_encoder import (
    KMeansEncoderAcousticRecogniser,
    eq_curves,
    equalised,
    triangle_encoding,
)
from tests.test_codebook import noise_scene

SMALL = {"n_codewords": 8, "n_codebooks": 2, "augment": 1}


@pytest.fixture(scope="module")
def trained() -> tuple[KMeansEncoderAcousticRecogniser, dict[str, np.ndarray]]:
    rng = np.random.default_rng(1)
    scenes = {
        "low": noise_scene(rng, 300, 6),
        "mid": noise_scene(rng, 1500, 6),
        "high": noise_scene(rng, 4000, 6),
    }
    model = KMeansEncoderAcousticRecogniser(**SMALL)
    X = model.featurize(np.concatenate(list(scenes.values())))
    model.fit(X, [s for s in scenes for _ in range(6)])
    return model, scenes


def test_triangle_encoding_small_exact_case() -> None:
    codewords = np.array([[0.0, 0.0], [3.0, 4.0]], np.float32)
    frames = np.array([[[0.0, 0.0], [3.0, 4.0]]], np.float32)  # one window, two frames
    # frame 0: distances (0, 5), mean 2.5 -> (2.5, 0); frame 1: (5, 0) -> (0, 2.5)
    np.testing.assert_allclose(triangle_encoding(frames, codewords), [[1.25, 1.25]], atol=1e-5)


def test_equaliser_colours_but_keeps_the_level() -> None:
    frames = np.zeros((4, 3, 10), np.float32)
    curves = eq_curves(10, 0.3, 4)
    assert curves.shape == (4, 10)
    for curve in curves:
        out = equalised(frames, curve)
        np.testing.assert_allclose(out.mean(axis=-1), 0.0, atol=1e-6)
        assert np.abs(out).max() > 0.01 and np.abs(out).max() <= 0.6 + 1e-6
    # evenly turned: no two curves alike, and they cancel out on average
    assert len({tuple(np.round(c, 6)) for c in curves}) == 4
    np.testing.assert_allclose(curves.mean(axis=0), 0.0, atol=1e-6)


def test_equalised_copies_do_not_depend_on_the_random_state(trained) -> None:
    """The random state picks the codebooks only: the frame statistics of every training row
    (the windows, their equalised copies, their crops) are the same under two random states.
    With equalisations drawn at random they were not, and few-shot figures swung with it."""
    _, scenes = trained
    X = KMeansEncoderAcousticRecogniser(**SMALL).featurize(
        np.concatenate([scenes["low"][:2], scenes["mid"][:2]])
    )
    fits = [
        KMeansEncoderAcousticRecogniser(**SMALL, random_state=seed).fit(
            X, ["low"] * 2 + ["mid"] * 2
        )
        for seed in (0, 1)
    ]
    statistics = 3 * X.shape[-1]
    a, b = (f.train_descriptors_[:, :statistics] for f in fits)
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6)
    assert not np.allclose(fits[0].codebooks_, fits[1].codebooks_)


def test_probabilities_sum_to_one_and_favour_the_truth(trained) -> None:
    model, scenes = trained
    rng = np.random.default_rng(5)
    for scene, centre in [("low", 300), ("mid", 1500), ("high", 4000)]:
        proba = model.predict_proba(model.featurize(noise_scene(rng, centre, 2)))
        np.testing.assert_allclose(proba.sum(axis=1), 1.0)
        assert np.all(np.argmax(proba, axis=1) == model.scenes_.index(scene))
    assert model.confidence_unit == "%"


def test_two_scenes_give_scikit_learns_probabilities(trained) -> None:
    model, scenes = trained
    X = model.featurize(np.concatenate([scenes["low"], scenes["mid"]]))
    # unsoftened, and no background: two classes, as scikit-learn keeps them
    two = KMeansEncoderAcousticRecogniser(**SMALL, temperature=1.0, background=False)
    two.fit(X, ["low"] * 6 + ["mid"] * 6)
    # the encodings' columns (after the 3 statistics a band) enter the head scaled
    weights = np.full(two.train_descriptors_.shape[1], two.encoding_weight)
    weights[: 3 * X.shape[-1]] = 1.0
    reference = LogisticRegression(C=two.C, class_weight="balanced", max_iter=3000).fit(
        two.train_descriptors_ * weights, two.train_scenes_
    )
    np.testing.assert_allclose(
        two.predict_proba(X), reference.predict_proba(two.descriptors(X) * weights), atol=1e-6
    )


def test_encoding_weight_leans_the_head_on_the_frame_statistics(trained) -> None:
    """A small `encoding_weight` makes the encodings' weights costly: the head's weight on them
    shrinks against the statistics', and at 0 it reads the statistics alone."""
    _, scenes = trained
    X = KMeansEncoderAcousticRecogniser(**SMALL).featurize(
        np.concatenate([scenes["low"][:3], scenes["mid"][:3]])
    )
    y = ["low"] * 3 + ["mid"] * 3
    statistics = 3 * X.shape[-1]

    def share(weight: float) -> float:
        model = KMeansEncoderAcousticRecogniser(**SMALL, encoding_weight=weight).fit(X, y)
        return float(np.abs(model.coef_[:, statistics:]).sum() / np.abs(model.coef_).sum())

    assert KMeansEncoderAcousticRecogniser().encoding_weight == 0.1
    assert share(0.1) < 0.5 * share(1.0)
    assert share(0.0) == 0.0
    with pytest.raises(ValueError, match="encoding_weight"):
        KMeansEncoderAcousticRecogniser(**SMALL, encoding_weight=-1.0).fit(X, y)


def test_a_model_file_saved_before_the_encoding_weight_refits_as_before(trained, tmp_path) -> None:
    """An older file has no `encoding_weight`: it loads at 1 (its head was fitted unscaled), its
    probabilities are those saved, and a fold-in refits the head as the old code did."""
    from tests.test_modelfile import rewrite_header

    _, scenes = trained
    X = KMeansEncoderAcousticRecogniser(**SMALL).featurize(
        np.concatenate([scenes["low"][:3], scenes["mid"][:3]])
    )
    y = ["low"] * 3 + ["mid"] * 3
    old = KMeansEncoderAcousticRecogniser(**SMALL, encoding_weight=1.0).fit(X, y)
    kept = load_model(save_model(tmp_path / "kept.npz", {"acoustic": old}))["acoustic"]
    path = save_model(tmp_path / "m.npz", {"acoustic": old})
    rewrite_header(path, lambda h: h["recognisers"]["acoustic"]["params"].pop("encoding_weight"))
    loaded = load_model(path)["acoustic"]
    assert loaded.encoding_weight == 1.0
    np.testing.assert_allclose(loaded.predict_proba(X), old.predict_proba(X))
    high = KMeansEncoderAcousticRecogniser(**SMALL).featurize(scenes["high"][:3])
    loaded.fold_in(high, ["high"] * 3)
    kept.fold_in(high, ["high"] * 3)
    np.testing.assert_allclose(loaded.coef_, kept.coef_)


def test_one_window_a_scene_does_not_collapse(trained) -> None:
    model, scenes = trained
    X = model.featurize(np.stack([scenes["low"][0], scenes["mid"][0], scenes["high"][0]]))
    taught = KMeansEncoderAcousticRecogniser(**SMALL).fit(X, ["low", "mid", "high"])
    rng = np.random.default_rng(9)
    for scene, centre in [("low", 300), ("mid", 1500), ("high", 4000)]:
        heard = taught.predict(taught.featurize(noise_scene(rng, centre, 2)))
        assert list(heard) == [scene] * 2  # nothing unknown yet: no spread can be measured


def test_far_window_is_unknown_and_fold_in_learns_it(trained) -> None:
    model, _ = trained
    model = KMeansEncoderAcousticRecogniser.from_state(*model.get_state())
    rng = np.random.default_rng(3)
    hiss = model.featurize(noise_scene(rng, 9000, 6))
    assert list(model.predict(hiss)) == [UNKNOWN] * 6
    model.fold_in(hiss, ["hiss"] * 6)
    assert "hiss" in model.scenes_
    assert list(model.predict(model.featurize(noise_scene(rng, 9000, 2)))) == ["hiss"] * 2


def test_model_file_round_trip(trained, tmp_path) -> None:
    model, scenes = trained
    path = save_model(tmp_path / "m.npz", {"acoustic": model})
    loaded = load_model(path)["acoustic"]
    X = model.featurize(scenes["mid"][:3])
    np.testing.assert_allclose(loaded.predict_proba(X), model.predict_proba(X))
    assert list(loaded.predict(X)) == list(model.predict(X))


@pytest.mark.parametrize("value", [0, 0.25, 1.5, -0.1])
def test_model_file_crop_fraction_is_a_part_of_a_window(trained, tmp_path, value) -> None:
    from tests.test_modelfile import refused_in_one_line, rewrite_header

    model, _ = trained
    path = save_model(tmp_path / "m.npz", {"acoustic": model})
    params = lambda h: h["recognisers"]["acoustic"]["params"]  # noqa: E731
    rewrite_header(path, lambda h: params(h).update(crop_fraction=value))
    if 0 <= value <= 1:
        assert load_model(path)["acoustic"].crop_fraction == value
    else:
        refused_in_one_line(path)


def with_temperature(model: KMeansEncoderAcousticRecogniser, temperature: float):
    header, arrays = model.get_state()
    header = {**header, "params": {**header["params"], "temperature": temperature}}
    return KMeansEncoderAcousticRecogniser.from_state(header, arrays)


def test_temperature_softens_the_probabilities_but_never_changes_a_decision(trained) -> None:
    model, _ = trained
    rng = np.random.default_rng(7)
    X = model.featurize(np.concatenate([noise_scene(rng, c, 3) for c in (300, 1500, 4000, 800)]))
    sharp, soft = with_temperature(model, 1.0), with_temperature(model, 3.0)
    p_sharp, p_soft = sharp.predict_proba(X), soft.predict_proba(X)
    np.testing.assert_allclose(p_soft.sum(axis=1), 1.0)
    assert list(soft.predict(X)) == list(sharp.predict(X))
    np.testing.assert_array_equal(np.argmax(p_soft, axis=1), np.argmax(p_sharp, axis=1))
    assert np.all(p_soft.max(axis=1) < p_sharp.max(axis=1))  # less sure of every window...
    logits = sharp.descriptors(X) @ sharp.coef_.T + sharp.intercept_
    expected = np.exp(logits / 3.0) / np.exp(logits / 3.0).sum(axis=1, keepdims=True)
    np.testing.assert_allclose(p_soft, expected, rtol=1e-6)  # ...as softmax(logits / T)
    truth = np.argmax(p_sharp, axis=1)
    loss = [float(-np.mean(np.log(p[np.arange(len(p)), truth]))) for p in (p_sharp, p_soft)]
    assert loss[1] > loss[0]  # on windows it names right, softer costs log loss


def test_a_model_file_saved_before_the_temperature_keeps_its_probabilities(
    trained, tmp_path
) -> None:
    from tests.test_modelfile import rewrite_header

    model, scenes = trained
    path = save_model(tmp_path / "m.npz", {"acoustic": with_temperature(model, 2.5)})
    rewrite_header(path, lambda h: h["recognisers"]["acoustic"]["params"].pop("temperature"))
    loaded = load_model(path)["acoustic"]
    assert loaded.temperature == 1.0  # as it was saved: no temperature then
    X = model.featurize(scenes["mid"][:3])
    np.testing.assert_allclose(
        loaded.predict_proba(X), with_temperature(model, 1.0).predict_proba(X)
    )


@pytest.mark.parametrize("value", [0, -1.0, 0.01, 1e6, 2.0])
def test_model_file_temperature_within_limits(trained, tmp_path, value) -> None:
    from tests.test_modelfile import refused_in_one_line, rewrite_header

    model, _ = trained
    path = save_model(tmp_path / "m.npz", {"acoustic": model})
    params = lambda h: h["recognisers"]["acoustic"]["params"]  # noqa: E731
    rewrite_header(path, lambda h: params(h).update(temperature=value))
    if value == 2.0:
        assert load_model(path)["acoustic"].temperature == 2.0
    else:
        refused_in_one_line(path, "parameter temperature is .* outside 0.1–10")


def test_a_temperature_at_or_below_zero_is_refused_by_fit(trained) -> None:
    model, scenes = trained
    X = model.featurize(np.concatenate([scenes["low"][:2], scenes["mid"][:2]]))
    with pytest.raises(ValueError, match="temperature"):
        KMeansEncoderAcousticRecogniser(**SMALL, temperature=0.0).fit(X, ["low"] * 2 + ["mid"] * 2)


def test_registered_and_unfitted_raises() -> None:
    model = make_recogniser("audio", "kmeans-encoder")
    with pytest.raises(NotFittedError):
        model.predict(np.zeros((1, 10, 40), np.float32))


# A small fixed subset of the real recordings: the first recording (by name) of each scene that
# has three or more. The whole library (84 recordings) and its targets are measured by
# bench/few_shot.py, not here: a test reads a few recordings, a bench all of them.
FEW_SHOT_SUBSET = {
    "beach": ["dusktide-cast-beach.mp3"],
    "cafe": ["audio-ambient-cafe.mp3"],
    "construction": ["citysoundscape-fro-construction-sound.mp3"],
    "crowd": ["audio-ambient-baseball-stadium-background.mp3"],
    "library": ["codingweb-library.mp3"],
    "office": ["csesoc-hackathon-c-office.mp3"],
    "station": ["datameditation-station.mp3"],
    "street": ["ambience-designer-street-sounds-2.mp3"],
    "supermarket": ["datameditation-shopping.mp3"],
    "vehicle": ["calmit-train.mp3"],
}


@pytest.mark.slow
def test_few_shot_on_the_real_recordings(shared_data, tmp_path) -> None:
    """Three windows of each real recording teach it; the later 40 % of each is recognised."""
    from servant_core.evaluate import evaluate_audio
    from servant_core.library import SceneLibrary
    from tests.conftest import link_library

    subset = {scene: (names, 0) for scene, names in FEW_SHOT_SUBSET.items()}
    library = SceneLibrary.scan(link_library(tmp_path / "lib", shared_data, subset))
    result = evaluate_audio(library, "kmeans-encoder", "fewshot", shots=(3,))
    assert result["rows"][0]["balanced_accuracy"] >= 0.92  # issue 11's target (0.880 before)


# -- a place taught on several visits ----------------------------------------------------------


@pytest.fixture(scope="module")
def visited(trained) -> KMeansEncoderAcousticRecogniser:
    """`outside` taught on two visits (a low hum six windows long, a hiss once), `inside` on one."""
    _, scenes = trained
    model = KMeansEncoderAcousticRecogniser(**SMALL)
    X = model.featurize(np.concatenate([scenes["low"], scenes["high"][:1], scenes["mid"][:3]]))
    scenes_ = ["outside"] * 7 + ["inside"] * 3
    return model.fit(X, scenes_, visits=["hum"] * 6 + ["hiss"] + ["in"] * 3)


def test_each_visit_of_a_place_is_a_row_of_the_head(visited) -> None:
    assert visited.scenes_ == ["inside", "outside"]
    assert sorted(visited.mode_scenes_.tolist()) == ["inside", "outside", "outside"]
    assert visited.coef_.shape[0] == 3


def test_a_place_is_its_likeliest_visit_and_open_is_all_its_visits_together(
    visited, trained
) -> None:
    """`predict_proba`: each place's likeliest visit, shares renormalised; `open_proba`: the
    probability of the place and not elsewhere, its visits summed."""
    from servant_core.recognisers.kmeans_encoder import softmax_proba

    _, scenes = trained
    D = visited.descriptors(visited.featurize(scenes["high"][1:4]))
    rows = np.vstack([visited.coef_, visited.elsewhere_coef_])
    intercept = np.concatenate([visited.intercept_, visited.elsewhere_intercept_])
    closed = softmax_proba((D @ visited.coef_.T + visited.intercept_) / visited.temperature)
    opened = softmax_proba((D @ rows.T + intercept) / visited.temperature)[:, :3]
    outside = visited.mode_scenes_ == "outside"
    best = np.stack([closed[:, ~outside].max(axis=1), closed[:, outside].max(axis=1)], axis=1)
    np.testing.assert_allclose(visited._proba(D), best / best.sum(axis=1, keepdims=True))
    together = np.stack([opened[:, ~outside].sum(axis=1), opened[:, outside].sum(axis=1)], axis=1)
    np.testing.assert_allclose(visited._open_proba(D), together)
    # the hiss heard once is still the outside
    assert list(visited.predict(visited.featurize(scenes["high"][1:4]))) == ["outside"] * 3


def test_windows_folded_in_are_a_new_visit(visited, trained) -> None:
    _, scenes = trained
    model = KMeansEncoderAcousticRecogniser.from_state(*visited.get_state())
    model.fold_in(model.featurize(scenes["mid"][3:5]), ["outside"] * 2)
    assert len(set(model.train_visits_.tolist())) == 4
    assert sorted(model.mode_scenes_.tolist()) == ["inside", "outside", "outside", "outside"]


def test_a_model_file_keeps_the_visits_and_one_from_before_has_one_a_place(
    visited, trained, tmp_path
) -> None:
    from tests.test_modelfile import refused_in_one_line, rewrite_arrays

    _, scenes = trained
    X = visited.featurize(scenes["high"][1:4])
    path = save_model(tmp_path / "m.npz", {"acoustic": visited})
    loaded = load_model(path)["acoustic"]
    np.testing.assert_allclose(loaded.predict_proba(X), visited.predict_proba(X))
    assert loaded.mode_scenes_.tolist() == visited.mode_scenes_.tolist()
    np.testing.assert_array_equal(loaded.train_visits_, visited.train_visits_)
    # saved before visits: no visit arrays, a head row a place
    model, _ = trained
    old = save_model(tmp_path / "old.npz", {"acoustic": model})
    rewrite_arrays(old, lambda a: [a.pop(f"acoustic/{k}") for k in ("train_visits", "mode_scenes")])
    before = load_model(old)["acoustic"]
    assert before.mode_scenes_.tolist() == before.scenes_
    np.testing.assert_allclose(before.predict_proba(X), model.predict_proba(X))
    # rows that name a place the model does not have: refused, in one line
    rewrite_arrays(path, lambda a: a["acoustic/mode_scenes"].__setitem__(0, "elsewhere"))
    refused_in_one_line(path, "head's rows do not match its places")


def test_visits_are_recordings_and_teach_presses_close_in_time(tmp_path) -> None:
    """A recording longer than a window is a visit of its own; one-window presses of a place
    made within half an hour of each other are one visit, a press a day later another."""
    import os

    from servant_core.library import Recording, WindowFeatures, visits_of

    made = {"long": 0, "press-1": 0, "press-2": 600, "press-3": 1500, "later": 86_400, "in": 0}
    recordings = []
    for name, offset in made.items():
        path = tmp_path / f"{name}.wav"
        path.write_bytes(b"")
        os.utime(path, (1_700_000_000 + offset, 1_700_000_000 + offset))
        recordings.append(Recording("inside" if name == "in" else "cafe", path))
    recording = np.array([0, 0, 0, 1, 2, 3, 4, 5])  # `long` has three windows
    wf = WindowFeatures(
        np.zeros((8, 1)), np.array(["cafe"] * 7 + ["inside"]), recording, np.zeros(8), recordings
    )
    visits = visits_of(wf)
    long, p1, p2, p3, later, inside = (visits[recording == i][0] for i in range(6))
    assert p1 == p2 == p3
    assert len({long, p1, later, inside}) == 4


# A small fixed subset with three recordings a scene (the first three by name of each scene that
# has three or more): a place heard through several recordings is several visits.
VISITS_SUBSET = {
    "beach": ["dusktide-cast-beach.mp3", "focusflow-beach.mp3", "loco-sound-v2-seaside.mp3"],
    "cafe": ["audio-ambient-cafe.mp3", "audionova-restaurant.mp3", "csesoc-hackathon-c-cafe.mp3"],
    "construction": [
        "citysoundscape-fro-construction-sound.mp3",
        "moodist-construction-site.mp3",
        "relaxandsleep-construction-site.mp3",
    ],
    "crowd": [
        "audio-ambient-baseball-stadium-background.mp3",
        "dusktide-cast-crowd.mp3",
        "loco-sound-v2-conversation.mp3",
    ],
    "library": ["codingweb-library.mp3", "focusflow-library.mp3", "moodist-library.mp3"],
    "office": [
        "csesoc-hackathon-c-office.mp3",
        "datameditation-office.mp3",
        "dusktide-cast-office.mp3",
    ],
    "station": [
        "datameditation-station.mp3",
        "moodist-subway-station.mp3",
        "somnio-train-station.mp3",
    ],
    "street": [
        "ambience-designer-street-sounds-2.mp3",
        "audio-ambient-city.mp3",
        "audionova-street-a17ffce.mp3",
    ],
    "supermarket": [
        "datameditation-shopping.mp3",
        "moodist-supermarket.mp3",
        "richwise-uk-supermarket.ogg",
    ],
    "vehicle": ["calmit-train.mp3", "codingweb-train.mp3", "datameditation-inthecar.mp3"],
}


@pytest.mark.slow
def test_one_window_of_each_of_three_recordings_a_place_on_the_real_recordings(
    shared_data, tmp_path
) -> None:
    """Teach mode's k = 1 on 30 real recordings (three a scene): each recording is a visit of its
    place. With a head row a place (visits ignored) this subset gives 0.758, with the visits
    0.925; the issue's k = 1 target is 0.85 (the whole library's: bench/few_shot.py)."""
    from servant_core.evaluate import evaluate_audio
    from servant_core.library import SceneLibrary
    from tests.conftest import link_library

    subset = {scene: (names, 0) for scene, names in VISITS_SUBSET.items()}
    library = SceneLibrary.scan(link_library(tmp_path / "lib", shared_data, subset))
    result = evaluate_audio(library, "kmeans-encoder", "fewshot", shots=(1,))
    assert result["rows"][0]["balanced_accuracy"] >= 0.85


def test_the_apps_retrain_learns_a_long_recording_and_the_presses_as_two_visits(tmp_path) -> None:
    """The library's retrain (teach mode's Retrain, the library screen's R) passes the visits:
    a 15 s recording of the street and two presses there are two visits; the café's one press
    is one."""
    from servant_core.audio import write_wav
    from servant_core.engine.learning import refit_audio
    from servant_core.library import SceneLibrary
    from tests.test_codebook import RATE

    rng = np.random.default_rng(4)
    street, cafe = noise_scene(rng, 4000, 5), noise_scene(rng, 300, 1)
    write_wav(tmp_path / "street" / "walk.wav", np.concatenate(street[:3]), RATE)
    for i in (3, 4):
        write_wav(tmp_path / "street" / f"teach-{i}.wav", street[i], RATE)
    write_wav(tmp_path / "cafe" / "teach-0.wav", cafe[0], RATE)
    model = refit_audio(
        SceneLibrary.scan(tmp_path), KMeansEncoderAcousticRecogniser(**SMALL), 5.0, print
    )
    assert sorted(model.mode_scenes_.tolist()) == ["cafe", "street", "street"]
