"""Parallel fusion: looks all the time, decides as soon as sound and pictures agree."""

import pytest

from servant_core.events import Decision
from servant_core.fusion import POLICIES, FusionConfig, ParallelFusion
from servant_core.recognisers import UNKNOWN


def decisions(events):
    return [e for e in events if isinstance(e, Decision)]


def test_pictures_seen_before_the_sound_confirm_it_at_once():
    fusion = ParallelFusion(votes_needed=2)
    assert fusion.wants_picture(0.0)  # looking before anything was heard
    assert decisions(fusion.on_visual("cafe", 60.0, 1.0)) == []
    assert decisions(fusion.on_visual("cafe", 80.0, 3.0)) == []
    [decision] = decisions(fusion.on_acoustic("cafe", 90.0, 5.0))
    assert decision.t == 5.0
    assert decision.line == "CafeScene detected"
    assert decision.confidence == pytest.approx((90.0 + 70.0) / 2)
    assert fusion.phase == "listening"


def test_a_wrong_sound_is_not_confirmed_by_a_stray_picture():
    fusion = ParallelFusion(votes_needed=2)
    fusion.on_acoustic("street", 90.0, 0.0)
    for t, scene in [(1.0, "cafe"), (3.0, "street"), (5.0, "cafe"), (7.0, "street")]:
        # street never leads the vote (1–1, then 1–2, then 2–2): no decision
        assert decisions(fusion.on_visual(scene, 80.0, t)) == []


def test_unknown_pictures_do_not_vote_and_unknown_sound_clears_the_opinion():
    fusion = ParallelFusion(votes_needed=2)
    fusion.on_visual("cafe", 80.0, 0.0)
    fusion.on_visual(UNKNOWN, 80.0, 2.0)
    fusion.on_acoustic(UNKNOWN, 0.0, 4.0)
    assert fusion.scene is None
    assert decisions(fusion.on_visual("cafe", 80.0, 6.0)) == []  # no sound to agree with
    [decision] = decisions(fusion.on_acoustic("cafe", 70.0, 9.0))
    assert decision.scene == "cafe"


def test_old_pictures_leave_the_window_and_silence_times_out():
    config = FusionConfig(acoustic_window_s=30.0, confirm_window_s=10.0)
    fusion = ParallelFusion(config, votes_needed=2)
    fusion.on_visual("cafe", 80.0, 0.0)
    fusion.on_acoustic("cafe", 90.0, 5.0)
    assert decisions(fusion.on_visual("cafe", 80.0, 12.0)) == []  # the t=0 picture is too old
    [decision] = decisions(fusion.tick(35.1))
    assert decision.line == "No scene detected"
    assert decision.confidence == 0.0


def stream(policy, acoustic, visual, horizon=60.0):
    """Enter a scene at t=0: a sound prediction at the end of each 5 s window, a picture whenever
    the policy asks (every 2 s); returns the first Decision."""
    for step in range(int(horizon * 2) + 1):
        t = step / 2
        events = policy.tick(t)
        if t > 0 and t % 5 == 0:
            events += policy.on_acoustic(acoustic, 90.0, t)
        if policy.wants_picture(t):
            events += policy.on_visual(visual[int(t) % len(visual)], 70.0, t)
        if decisions(events):
            return decisions(events)[0]
    return None


def test_streaming_parallel_decides_when_the_first_window_ends_sequential_later():
    config = FusionConfig()  # the paper's: 3 agreeing pictures within 20 s, 30 s window
    visual = ["cafe", "cafe", "street"]
    parallel = stream(ParallelFusion(config), "cafe", visual)
    sequential = stream(POLICIES["sequential"](config), "cafe", visual)
    assert parallel.scene == sequential.scene == "cafe"
    # pictures at 0, 2, 4 s say cafe, street, cafe: cafe leads with two votes when heard at 5 s
    assert parallel.t == 5.0
    assert sequential.t > 5.0 + 2 * config.picture_interval_s  # it starts looking only at 5 s
    three = stream(ParallelFusion(config, votes_needed=3), "cafe", visual)
    assert three.t == 6.0  # the picture at 6 s is the third cafe
