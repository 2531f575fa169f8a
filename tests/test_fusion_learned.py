"""The learned fusion (issue 12): the net over every sense's probabilities, and its policy."""

import numpy as np
import pytest

from servant_core.errors import ServantError
from servant_core.events import Decision
from servant_core.fusion import POLICIES, FusionConfig, LearnedFusion, ParallelFusion
from servant_core.fusion.learning import (
    contiguous_folds,
    order_folds,
    train_fusion_net,
)
from servant_core.fusion.net import (
    FLAGS,
    LEGACY_FLAGS,
    FusionNet,
    SenseOpinions,
    precision_threshold,
    teaching_shortfall,
    training_rows,
)
from servant_core.recognisers import UNKNOWN

SCENES = ["cafe", "gym", "street"]


def said(rng, n, accuracy, scenes=SCENES, folds=4, unknown=0.0):
    """Made-up held-out opinions of one sense: right `accuracy` of the time, sure of itself
    either way; `unknown` of them said `<unknown>` (with flat probabilities)."""
    truth = np.array([scenes[i % len(scenes)] for i in range(n)])
    proba = np.full((n, len(scenes)), 0.05)
    predicted = []
    for i, scene in enumerate(truth):
        j = scenes.index(scene) if rng.random() < accuracy else int(rng.integers(len(scenes)))
        proba[i, j] = 0.9
        if rng.random() < unknown:
            proba[i] = 1.0 / len(scenes)
            predicted.append(UNKNOWN)
        else:
            predicted.append(scenes[j])
    proba /= proba.sum(axis=1, keepdims=True)
    return SenseOpinions(proba, list(scenes), np.array(predicted), truth, np.arange(n) % folds)


@pytest.fixture(scope="module")
def net():
    rng = np.random.default_rng(0)
    opinions = {"audio": said(rng, 120, 0.97), "image": said(rng, 240, 0.6, unknown=0.1)}
    return FusionNet(random_state=0).fit(opinions)


def audio_says(scene, p=0.9):
    rest = (1 - p) / (len(SCENES) - 1)
    return {s: (p if s == scene else rest) for s in SCENES}


def decisions(events):
    return [e for e in events if isinstance(e, Decision)]


def test_precision_threshold_is_the_lowest_that_keeps_the_target():
    top = np.array([0.99, 0.95, 0.9, 0.8, 0.7, 0.6])
    right = np.array([True, True, True, False, True, False])
    assert precision_threshold(top, right, 1.0) == 0.9
    assert precision_threshold(top, right, 0.8) == 0.7  # 4 of 5 right down to 0.7
    assert precision_threshold(top, np.zeros(6, bool), 0.5) == 1.0  # never good enough
    # a tie at the threshold decides both rows, so it may not be the threshold
    assert precision_threshold(np.array([0.9, 0.8, 0.8]), np.array([True, True, False]), 1.0) > 0.8


def test_training_rows_drop_senses_but_never_all():
    rng = np.random.default_rng(1)
    opinions = {"audio": said(rng, 30, 1.0), "image": said(rng, 30, 1.0)}
    X, y = training_rows(opinions, ["audio", "image"], SCENES, [0, 1, 2, 3], 3, 3, rng)
    width = len(SCENES) + FLAGS
    absent = X[:, [len(SCENES), width + len(SCENES)]]
    naming_nothing = X[:, [len(SCENES) + 1, width + len(SCENES) + 1]]
    pooled = X[:, [len(SCENES) + 2, width + len(SCENES) + 2]]
    assert len(X) == 4 * 30 and len(y) == len(X)  # each row whole and in 3 dropped copies
    dropped = absent + naming_nothing
    assert dropped.sum(axis=1).max() == 1  # never both dropped
    assert 0.2 < dropped.mean() < 0.5  # about half of each copy's senses dropped
    assert 0.05 < absent.mean() and 0.05 < naming_nothing.mean()  # in both ways
    assert np.all(X[absent[:, 0] == 1, : len(SCENES)] == 0)  # an absent sense says nothing
    flat = X[naming_nothing[:, 0] == 1, : len(SCENES)]
    assert np.allclose(flat, 1 / len(SCENES))  # a sense naming nothing favours no scene
    # how many opinions each present sense pooled, 1..3 of 3
    assert set(np.round(pooled[absent[:, 0] == 0, 0] * 3).tolist()) == {1.0, 2.0, 3.0}


def test_folds_follow_time_within_a_recording_and_file_order_within_a_scene():
    recording = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    position = np.array([3, 2, 1, 0, 0, 1, 2, 3])
    assert contiguous_folds(recording, position, 2).tolist() == [1, 1, 0, 0, 0, 0, 1, 1]
    assert order_folds(["a", "b", "a", "b", "a", "b"], 3).tolist() == [0, 0, 1, 1, 2, 2]


def test_too_little_taught_falls_back_to_the_parallel_policy():
    rng = np.random.default_rng(2)
    one_scene = {"audio": said(rng, 40, 1.0, scenes=["cafe"])}
    assert "two taught scenes" in teaching_shortfall(one_scene, 5)
    few = {"audio": said(rng, 6, 1.0)}  # two windows a scene
    assert "too few of cafe, gym, street" in teaching_shortfall(few, 5)
    net, reason = train_fusion_net(few)
    assert net is None and "per scene" in reason
    with pytest.raises(ServantError, match="per scene"):
        FusionNet().fit(few)
    fusion = POLICIES["learned"](FusionConfig())  # as the registry builds it: no net
    rule = ParallelFusion(FusionConfig())
    for policy in (fusion, rule):
        policy.on_visual("cafe", 70.0, 0.0)
        policy.on_visual("cafe", 70.0, 2.0)
    assert decisions(fusion.on_acoustic("cafe", 80.0, 3.0)) == decisions(
        rule.on_acoustic("cafe", 80.0, 3.0)
    )


def test_the_net_trusts_the_sure_sense_and_does_without_a_missing_one(net):
    assert 0.5 < net.threshold_ < 1.0
    assert net.senses_ == ["audio", "image"] and net.scenes_ == SCENES
    both = net.features({"audio": (audio_says("gym"), 0.0), "image": (audio_says("gym"), 0.0)})
    audio_only = net.features({"audio": (audio_says("street"), 0.0)})
    image_only = net.features({"image": (audio_says("cafe"), 0.0)})
    proba = net.predict_proba(np.vstack([both, audio_only, image_only]))
    assert net.predict(np.vstack([both, audio_only, image_only])).tolist() == [
        "gym",
        "street",
        "cafe",
    ]
    assert proba[0].max() >= net.threshold_ and proba[1].max() >= net.threshold_
    assert proba[2].max() < proba[1].max()  # one unsure picture is worth less than a sound
    # a sound and a picture that disagree: the sure sense wins
    clash = net.features({"audio": (audio_says("gym"), 0.0), "image": (audio_says("cafe"), 0.0)})
    assert net.predict(clash[None, :]).tolist() == ["gym"]


def test_the_policy_decides_says_what_it_leaned_on_and_starts_afresh(net):
    fusion = LearnedFusion(FusionConfig(), net)
    # the sure sense decides within a few windows (one window of a 0.97 sense may not be enough)
    for t in (1.0, 6.0, 11.0):
        said_gym = decisions(fusion.on_acoustic("gym", 90.0, t, scores=audio_says("gym")))
        if said_gym:
            break
    [decision] = said_gym
    assert decision.scene == "gym" and decision.line == "GymScene detected"
    assert decision.confidence >= 100 * net.threshold_ and decision.confidence_unit == "%"
    assert decision.leaned_on == ("audio",)
    assert decision.acoustic_confidence == 90.0
    assert fusion.state(decision.t).phase == "listening"


def test_a_stale_sense_counts_as_absent(net):
    fusion = LearnedFusion(FusionConfig(), net, staleness={"audio": 4.0, "image": 4.0})
    flat = dict.fromkeys(SCENES, 1 / 3)
    assert decisions(fusion.on_acoustic(UNKNOWN, 40.0, 0.0, scores=flat)) == []
    assert decisions(fusion.on_visual("cafe", 60.0, 1.0, scores=audio_says("cafe", 0.6))) == []
    fusion.tick(6.0)
    assert fusion.opinions == {"audio": [], "image": []}
    assert fusion.state(6.0).pictures_taken == 0


def test_without_a_decision_the_window_closes_with_no_scene(net):
    fusion = LearnedFusion(FusionConfig(acoustic_window_s=10.0), net)
    flat = dict.fromkeys(SCENES, 1 / 3)
    assert decisions(fusion.on_sense("image", UNKNOWN, 0.0, 0.0, flat)) == []
    assert fusion.wants_picture(2.0) and not fusion.wants_picture(1.0)
    [decision] = decisions(fusion.tick(10.5))
    assert decision.scene is None and decision.line == "No scene detected"


def test_a_sense_the_net_was_not_taught_is_ignored(net):
    fusion = LearnedFusion(FusionConfig(), net)
    assert decisions(fusion.on_sense("motion", "gym", 99.0, 0.0, audio_says("gym"))) == []
    [decision] = decisions(fusion.on_sense("audio", "gym", 99.0, 1.0))  # no scores: one-hot
    assert decision.scene == "gym" and decision.leaned_on == ("audio",)


def test_state_round_trip_decides_the_same(net):
    header, arrays = net.get_state()
    loaded = FusionNet.from_state(header, arrays)
    rng = np.random.default_rng(3)
    X = rng.random((20, len(net.senses_) * (len(SCENES) + FLAGS)))
    assert np.array_equal(loaded.predict_proba(X), net.predict_proba(X))
    assert loaded.threshold_ == net.threshold_ and loaded.scenes_ == net.scenes_
    assert header["params"]["hidden_layer_sizes"] == [24]


def test_two_scenes_work_through_the_single_logistic_output():
    rng = np.random.default_rng(4)
    two = ["cafe", "gym"]
    opinions = {"audio": said(rng, 60, 0.95, two), "image": said(rng, 60, 0.8, two)}
    net = FusionNet(random_state=0).fit(opinions)
    assert net.coefs_[-1].shape[1] == 1
    row = net.features({"audio": ({"cafe": 0.05, "gym": 0.95}, 0.0)})
    proba = net.predict_proba(row)
    assert proba.shape == (1, 2) and proba[0, 1] > 0.5 and proba.sum() == pytest.approx(1.0)


def test_sense_dropout_makes_the_net_better_without_a_sense():
    """Trained where the picture is always right, a net without dropout leans on it; with the
    picture missing it is worse than a net that was shown rows without it."""
    from sklearn.metrics import log_loss

    rng = np.random.default_rng(9)
    missing_picture = {"audio": said(rng, 120, 0.8)}
    X, y = training_rows(missing_picture, ["audio", "image"], SCENES, [0, 1, 2, 3], 5, 0, rng)
    rng = np.random.default_rng(0)
    opinions = {"audio": said(rng, 120, 0.8), "image": said(rng, 120, 1.0)}
    losses = [
        log_loss(y, FusionNet(dropout_copies=c).fit(opinions).predict_proba(X), labels=SCENES)
        for c in (0, 3)
    ]
    assert losses[1] < 0.8 * losses[0]


def test_a_sense_that_names_no_scene_never_decides_alone(net):
    """Before: the net had hardly seen a sense say `<unknown>`, and read a flat unknown opinion
    as near-certainty of some scene (1.00 on the real data); the arm would move at a new place."""
    fusion = LearnedFusion(FusionConfig(), net)
    flat = dict.fromkeys(SCENES, 1 / 3)
    events = [fusion.on_acoustic(UNKNOWN, 50.0, t, scores=flat) for t in (0.0, 5.0, 10.0, 15.0)]
    assert decisions([e for said in events for e in said]) == []
    proba = net.predict_proba(net.features({"audio": (flat, 1.0, 4)}))
    assert proba.max() < net.threshold_


def test_one_picture_is_a_glimpse_three_can_decide():
    """Without sound the camera decides only once it has shown `pictures_needed` pictures:
    before, the first confident picture decided (on the real data 90 of 215 encounters without
    sound, 77 % of them right)."""
    rng = np.random.default_rng(5)
    opinions = {"audio": said(rng, 120, 0.97), "image": said(rng, 240, 0.95)}
    net = FusionNet(random_state=0).fit(opinions)
    fusion = LearnedFusion(FusionConfig(), net)
    first = fusion.on_visual("cafe", 90.0, 0.0, scores=audio_says("cafe", 0.98))
    assert decisions(first) == []
    later = [fusion.on_visual("cafe", 90.0, t, scores=audio_says("cafe", 0.98)) for t in (2.0, 4.0)]
    [decision] = decisions([e for said in later for e in said])
    assert decision.scene == "cafe" and decision.t == 4.0 and decision.leaned_on == ("image",)


def test_a_net_saved_before_the_count_was_read_still_loads_and_decides(net):
    """Nets saved by the previous version read two flags per sense (absent, unknown)."""
    header, arrays = net.get_state()
    del header["flags"]
    width = len(SCENES) + LEGACY_FLAGS
    rng = np.random.default_rng(6)
    arrays = dict(arrays, coef_0=rng.normal(size=(2 * width, 24)))
    old = FusionNet.from_state(header, arrays)
    row = old.features({"audio": (audio_says("gym"), 0.0)})
    assert row.shape == (2 * width,) and old.predict_proba(row).shape == (1, len(SCENES))
    with pytest.raises(ValueError, match="layer 0"):
        FusionNet.from_state(dict(header, flags=FLAGS), arrays)
