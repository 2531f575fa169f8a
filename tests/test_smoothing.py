"""The forward filter over windows: exact steps, one odd window, a real change, unknown."""

from __future__ import annotations

import pytest

from servant_core.fusion.smoothing import SceneSmoother, forward_step
from servant_core.recognisers import UNKNOWN

CAFE = {"cafe": 0.9, "street": 0.05, "office": 0.05}
STREET = {"cafe": 0.05, "street": 0.9, "office": 0.05}
SURE_STREET = {"cafe": 0.0, "street": 1.0, "office": 0.0}


def decided(scores: dict[str, float]) -> str:
    return max(scores, key=lambda s: scores[s])


def settled_in_cafe(smoother: SceneSmoother) -> SceneSmoother:
    for _ in range(10):
        smoother.update(CAFE)
    return smoother


def test_first_window_is_its_floored_evidence() -> None:
    out = forward_step({}, {"a": 1.0, "b": 0.0}, stay=0.9, floor=0.2)
    assert out == pytest.approx({"a": 0.9, "b": 0.1})  # 0.8·1 + 0.2/2, 0.8·0 + 0.2/2


def test_no_evidence_only_moves_belief_by_the_transition() -> None:
    # kept with 0.7, else drawn afresh: 0.3/3 to each scene, itself included
    out = forward_step({"a": 1.0, "b": 0.0, "c": 0.0}, {}, stay=0.7, floor=0.1)
    assert out == pytest.approx({"a": 0.8, "b": 0.1, "c": 0.1})


def test_one_step_is_prior_times_evidence() -> None:
    # prior a = 0.9·0.5 + 0.1/2 = 0.5 (two states); evidence a = 0.5·0.6 + 0.25 = 0.55,
    # b = 0.5·0.4 + 0.25 = 0.45
    out = forward_step({"a": 0.5, "b": 0.5}, {"a": 0.6, "b": 0.4}, stay=0.9, floor=0.5)
    assert out == pytest.approx({"a": 0.55, "b": 0.45})


def test_one_odd_window_does_not_flip_the_scene() -> None:
    smoother = settled_in_cafe(SceneSmoother(stay=0.95, floor=0.1))
    assert decided(smoother.update(SURE_STREET)) == "cafe"
    assert decided(smoother.update(CAFE)) == "cafe"


def test_without_the_filter_the_odd_window_would_flip() -> None:
    assert decided(SURE_STREET) == "street"  # the raw decision the filter holds back


def test_a_real_change_shows_within_two_windows() -> None:
    smoother = settled_in_cafe(SceneSmoother(stay=0.95, floor=0.1))
    first = smoother.update(STREET)
    second = smoother.update(STREET)
    assert decided(first) == "cafe"
    assert decided(second) == "street"


def test_staying_is_never_less_likely_than_moving() -> None:
    # a low stay with two scenes still keeps the belief where it was, if only a little
    out = forward_step({"a": 1.0, "b": 0.0}, {}, stay=0.2, floor=0.1)
    assert out["a"] > out["b"]


def test_probabilities_sum_to_one() -> None:
    smoother = SceneSmoother()
    for scores in (CAFE, STREET, {}, {"cafe": 3.0, "street": 1.0}):
        assert sum(smoother.update(scores).values()) == pytest.approx(1.0)


def test_unknown_is_a_persistent_state_too() -> None:
    smoother = settled_in_cafe(SceneSmoother(stay=0.95, floor=0.1))
    elsewhere = {UNKNOWN: 1.0}
    assert decided(smoother.update(elsewhere)) == "cafe"
    assert decided(smoother.update(elsewhere)) == UNKNOWN


def test_a_scene_folded_in_later_joins_the_states() -> None:
    smoother = settled_in_cafe(SceneSmoother(stay=0.95, floor=0.1))
    kitchen = {"cafe": 0.02, "street": 0.02, "office": 0.02, "kitchen": 0.94}
    assert "kitchen" in smoother.update(kitchen)
    assert decided(smoother.update(kitchen)) == "kitchen"


def test_reset_forgets_the_past() -> None:
    smoother = settled_in_cafe(SceneSmoother(stay=0.95, floor=0.1))
    smoother.reset()
    assert decided(smoother.update(SURE_STREET)) == "street"


@pytest.mark.parametrize(("stay", "floor"), [(0.0, 0.1), (1.0, 0.1), (0.9, 0.0), (0.9, 1.5)])
def test_settings_out_of_range_are_refused(stay: float, floor: float) -> None:
    with pytest.raises(ValueError):
        SceneSmoother(stay, floor)
