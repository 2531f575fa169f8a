"""Stable live decisions in the engine: consecutive windows' probabilities go through the forward
filter, so one odd window does not flip the scene while a real change shows by its second window.
The demo's recognisers and synthesised windows, replayed on a manual clock."""

from __future__ import annotations

import numpy as np

from servant_core.capture.replay import Clip, PacedAudio
from servant_core.capture.source import ManualClock
from servant_core.demo.audio_synth import DEMO_RATE
from servant_core.demo.scenes import synth_window
from servant_core.engine import Engine, steady
from servant_core.events import AcousticPrediction
from tests.conftest import demo_recognisers

# a café with one window of street noise in it (a door opened), then a real walk outside
HEARD = ["coffee"] * 4 + ["street"] + ["coffee"] * 3 + ["street"] * 4


def heard(smoother) -> list[str | None]:
    acoustic, _ = demo_recognisers(paper=False)
    clock = ManualClock()
    clips = [Clip(s, synth_window(s, np.random.default_rng([42, k]))) for k, s in enumerate(HEARD)]
    engine = Engine(
        audio=PacedAudio(clips, DEMO_RATE, realtime=False, clock=clock),
        acoustic=acoustic,
        clock=clock,
        smoother=smoother,
    )
    events: list = []
    engine.subscribe(events.append)
    engine.run_until(1e9)
    return [e.scene for e in events if isinstance(e, AcousticPrediction)]


def test_each_window_alone_follows_the_odd_window():
    assert heard(None) == HEARD  # the recogniser hears every window right, the odd one too


def test_smoothed_one_odd_window_does_not_flip_and_a_real_change_shows_by_its_second_window():
    scenes = heard(steady())
    assert scenes[:8] == ["coffee"] * 8  # the door: no flip
    assert scenes[9:] == ["street"] * 3  # outside: street from the second window on
