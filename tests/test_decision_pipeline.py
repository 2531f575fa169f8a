"""One decision pipeline (issue 40): the live engine and `servant predict`'s path decide alike
on the same opinions, whatever the policy and whether the sound knows somewhere else.

The recognisers here are scripted stand-ins (their k-th window or picture gives the k-th scripted
opinion): what is compared is what is decided of opinions, not how opinions are formed, which
the recognisers' own tests cover."""

from __future__ import annotations

import numpy as np
import pytest

from servant_core.capture.source import ManualClock
from servant_core.engine import Engine
from servant_core.evaluate import run_encounter
from servant_core.events import Decision
from servant_core.fusion import POLICIES, FusionConfig, LearnedFusion
from servant_core.fusion.pipeline import ARRIVE_SURE, DecisionPipeline
from servant_core.recognisers import UNKNOWN
from servant_core.recognisers.base import Capabilities

RATE = 16000
CAFE = {"cafe": 0.8, "street": 0.05}  # the sound's probabilities (open: 0.15 elsewhere)
PICTURES = [
    ("cafe", 90.0, {"cafe": 0.9, "street": 0.1}),
    ("street", 60.0, {"cafe": 0.4, "street": 0.6}),
    ("cafe", 70.0, {"cafe": 0.7, "street": 0.3}),
]


class Scripted(Capabilities):
    """A recogniser whose k-th featurized item gives `said[k % len(said)]`; it declares it can
    do nothing beyond the protocol (`Capabilities`' defaults)."""

    confidence_unit = "%"
    window_seconds = 5.0
    rate = RATE

    def __init__(self, sense: str, said: list, open_: bool) -> None:
        self.sense = sense
        self.said = said
        self.knows_elsewhere = open_
        self.scenes_ = np.array(sorted(said[0][2]))
        self.items = 0

    def featurize(self, items) -> np.ndarray:
        self.items += 1
        return np.array([[float(self.items - 1)]])

    def answers(self, X: np.ndarray):
        scene, confidence, scores = self.said[int(X[0, 0]) % len(self.said)]
        proba = np.array([[scores[s] for s in self.scenes_]])
        return np.array([scene]), np.array([confidence]), proba


def engine_decision(policy, config, sound, open_sound) -> Decision | None:
    """The engine's decision: the sound's window twice (a sound that knows elsewhere names a
    place when two windows in a row say so), then a picture whenever the policy asks, on a
    manual clock stepped as the engine's loop looks."""
    clock = ManualClock(start=-5.0)
    acoustic = Scripted("audio", [sound], open_sound)
    engine = Engine(
        acoustic=acoustic,
        visual=Scripted("image", PICTURES, False),
        fusion=policy,
        clock=clock,
    )
    decisions: list[Decision] = []
    engine.subscribe(lambda e: decisions.append(e) if isinstance(e, Decision) else None)
    engine._arm.act = lambda *args: None  # no arm here: the decision is what is compared
    window = np.random.default_rng(0).normal(0, 0.1, RATE * 5).astype(np.float32)
    engine._judge.on_window(window, RATE)
    clock.advance(5.0)
    engine._judge.on_window(window, RATE)
    step = config.picture_interval_s / 4
    while not decisions and clock() < config.acoustic_window_s + 10:
        t = clock.advance(step)
        engine._judge.handle(engine.decisions.tick(t))
        if not decisions and engine.decisions.wants_picture(t):
            engine._judge.on_picture(np.zeros((8, 8, 3), np.uint8), t)
    return decisions[0] if decisions else None


@pytest.mark.parametrize("open_sound", [True, False])
@pytest.mark.parametrize("policy", ["sequential", "parallel", "learned"])
def test_the_engine_and_predict_decide_alike(policy, open_sound):
    config = FusionConfig()
    make = (
        (lambda: LearnedFusion(config))
        if policy == "learned"
        else (lambda: POLICIES[policy](config))
    )
    sound = ("cafe", 80.0, CAFE)
    live = engine_decision(make(), config, sound, open_sound)
    open_roles = ["acoustic"] if open_sound else []
    predicted = run_encounter(make(), config, sound, PICTURES, open_roles)
    assert live is not None
    said = (predicted.scene, predicted.line, predicted.leaned_on, predicted.not_elsewhere)
    assert (live.scene, live.line, live.leaned_on, live.not_elsewhere) == said
    assert live.confidence == pytest.approx(predicted.confidence)


def test_a_sound_likelier_elsewhere_decides_nothing_on_either_path():
    config = FusionConfig()
    sound = ("cafe", 30.0, {"cafe": 0.3, "street": 0.1})  # elsewhere 0.6
    live = engine_decision(POLICIES["parallel"](config), config, sound, True)
    predicted = run_encounter(POLICIES["parallel"](config), config, sound, PICTURES, ["acoustic"])
    assert predicted.scene is None
    assert live is None or live.scene is None


def test_the_pipeline_holds_an_open_sound_over_two_windows_and_forgets():
    pipeline = DecisionPipeline(POLICIES["parallel"](FusionConfig()))
    likely = {"cafe": 0.7, "street": 0.05}  # likelier than not, below ARRIVE_SURE
    first = pipeline.hear("cafe", 70.0, likely, "%", True)
    assert first[0] == UNKNOWN  # one window alone names no place
    second = pipeline.hear("cafe", 70.0, likely, "%", True)
    assert second[0] == "cafe" and second[1] == pytest.approx(70.0)
    pipeline.forget()
    assert pipeline.hear("cafe", 70.0, likely, "%", True)[0] == UNKNOWN


def test_one_sure_window_names_a_place_arriving_unless_it_is_far_or_the_rule_is_off():
    """Issue 39's wait from a taught place to the arm: one window more for the steadying. A
    window that gives a place ARRIVE_SURE or more names it at once."""
    sure = {"cafe": ARRIVE_SURE, "street": 0.05}
    pipeline = DecisionPipeline(POLICIES["parallel"](FusionConfig()))
    scene, confidence, held = pipeline.hear("cafe", 80.0, sure, "%", True)
    assert scene == "cafe" and confidence == pytest.approx(100 * ARRIVE_SURE)
    assert held == sure
    pipeline.forget()
    # the recogniser's own answer: unknown, far from every taught window, though its
    # probabilities lean to the café: not named on one window
    assert pipeline.hear(UNKNOWN, 0.0, sure, "%", True)[0] == UNKNOWN
    off = DecisionPipeline(POLICIES["parallel"](FusionConfig()), arrive_sure=None)
    assert off.hear("cafe", 80.0, sure, "%", True)[0] == UNKNOWN
