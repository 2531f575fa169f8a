import pytest

from servant_core.events import Decision, FusionState
from servant_core.fusion import FusionConfig, SequentialFusion, scene_line
from servant_core.recognisers import UNKNOWN


def decisions(events):
    return [e for e in events if isinstance(e, Decision)]


@pytest.mark.parametrize(
    "scene, line",
    [
        ("coffee", "CoffeeScene detected"),
        ("coffee_shop", "CoffeeShopScene detected"),
        (None, "No scene detected"),
    ],
)
def test_scene_line(scene, line):
    assert scene_line(scene) == line


def test_detection_averages_the_two_confidences():
    fusion = SequentialFusion(FusionConfig(pictures_needed=2))
    fusion.on_acoustic("coffee", 90.0, 0.0)
    assert decisions(fusion.on_visual("coffee", 80.0, 2.0)) == []
    [decision] = decisions(fusion.on_visual("coffee", 70.0, 4.0))
    assert decision.line == "CoffeeScene detected"
    assert decision.confidence == pytest.approx((90 + 75) / 2)
    assert fusion.phase == "listening"


def test_last_picture_at_29_9_s_confirms_but_30_1_s_is_too_late():
    for t_last, expected in [(29.9, "CoffeeScene detected"), (30.1, "No scene detected")]:
        fusion = SequentialFusion(FusionConfig(pictures_needed=2))
        fusion.on_acoustic("coffee", 90.0, 100.0)
        fusion.on_visual("coffee", 80.0, 100.0 + 15.0)
        [decision] = decisions(fusion.on_visual("coffee", 80.0, 100.0 + t_last))
        assert decision.line == expected
        if expected.startswith("No"):
            assert decision.confidence == 0.0


def test_confirming_pictures_must_fall_within_the_confirmation_window():
    fusion = SequentialFusion(FusionConfig(pictures_needed=2, confirm_window_s=20.0))
    fusion.on_acoustic("gym", 90.0, 0.0)
    fusion.on_visual("gym", 80.0, 1.0)
    assert decisions(fusion.on_visual("gym", 80.0, 21.5)) == []  # 20.5 s apart: the first expired
    [decision] = decisions(fusion.on_visual("gym", 80.0, 25.0))
    assert decision.scene == "gym"


def test_timeout_restarts_and_mismatches_never_detect():
    fusion = SequentialFusion(FusionConfig(pictures_needed=1))
    fusion.on_acoustic("coffee", 90.0, 0.0)
    for t in range(2, 30, 2):
        assert decisions(fusion.on_visual("gym", 80.0, float(t))) == []
    [decision] = decisions(fusion.tick(30.01))
    assert decision.scene is None and decision.line == "No scene detected"
    # after the restart a picture alone decides nothing; a new sound opens a new window
    assert fusion.on_visual("gym", 80.0, 31.0) == []
    fusion.on_acoustic("gym", 90.0, 32.0)
    [decision] = decisions(fusion.on_visual("gym", 80.0, 33.0))
    assert decision.line == "GymScene detected"


def test_unknown_sound_opens_no_window_and_pictures_are_paced():
    config = FusionConfig(picture_interval_s=2.0)
    fusion = SequentialFusion(config)
    assert fusion.on_acoustic(UNKNOWN, 50.0, 0.0) == []
    assert not fusion.wants_picture(0.0)
    [state] = fusion.on_acoustic("cafe", 90.0, 1.0)
    assert (
        isinstance(state, FusionState) and state.phase == "looking" and state.seconds_left == 30.0
    )
    assert fusion.wants_picture(1.0)
    fusion.on_visual("street", 80.0, 1.0)
    assert not fusion.wants_picture(2.5) and fusion.wants_picture(3.0)
    # a second sound while looking is ignored, as in the paper
    fusion.on_acoustic("street", 95.0, 4.0)
    assert fusion.state(4.0).scene == "cafe" and fusion.state(4.0).pictures_taken == 1
