"""Which events a log says (`servant_core.log_news`), in small exact cases: the rule that
`servant run --headless` and the TUI's log share."""

from __future__ import annotations

from servant_core.events import AcousticPrediction, ArmState, Decision, Notice
from servant_core.log_news import LogNews, News

CAFE = {"cafe": 0.9, "street": 0.05}


def heard(t: float, scene: str | None, scores: dict[str, float] | None = None):
    return AcousticPrediction(t, scene, 90.0 if scene else 0.0, scores or {}, "%")


def decided(t: float, scene: str | None) -> Decision:
    return Decision(t, scene, 90.0 if scene else 0.0, f"{scene} detected" if scene else "none")


def arm(t: float, armed: bool, pose_of: str | None = None, shoulder: float = 10.0) -> ArmState:
    return ArmState(t, True, armed, "maestro", "/dev/pts/3", {"shoulder": shoulder}, None, pose_of)


def test_a_decision_is_said_when_it_changes_not_at_every_window():
    news = LogNews()
    said = [news(decided(t, s)).said for t, s in enumerate(["cafe", "cafe", "gym", "gym", "cafe"])]
    assert said == [True, False, True, False, True]
    assert news(decided(9.0, None)).said and not news(decided(10.0, None)).said


def test_the_arm_is_said_when_it_moves_or_its_state_changes_not_when_it_holds():
    news = LogNews()
    states = [
        arm(0.0, False),
        arm(1.0, False),
        arm(2.0, True),
        arm(3.0, True, shoulder=40.0),  # a move cut short: still armed, nothing new to say
        arm(4.0, True, "cafe", 40.0),
        arm(9.0, True, "gym", 50.0),
        arm(14.0, True),
        arm(15.0, False),
    ]
    assert [news(s).said for s in states] == [True, False, True, False, True, True, False, True]


def test_a_place_decided_is_left_once_when_the_sound_stops_naming_a_place():
    news = LogNews()
    assert news(heard(5.0, "cafe", CAFE)) == News(True)
    news(decided(5.0, "cafe"))
    assert news(heard(10.0, None, {"cafe": 0.1})) == News(True, left="cafe")
    assert news(heard(15.0, None, {"cafe": 0.1})) == News(True)
    assert not news(decided(16.0, None)).said  # a policy's own "No scene detected": said
    news(heard(20.0, "cafe", CAFE))
    assert news(decided(20.0, "cafe")).said  # back at the café: news again


def test_a_decision_made_while_the_sound_names_no_place_is_not_left_at_every_window():
    """A policy hearing every sense may name a place from the pictures while the sound names
    none: said once, and not left and decided again at every window."""
    news = LogNews()
    news(heard(5.0, None, {"cafe": 0.3}))
    assert news(decided(5.0, "cafe")).said
    for t in (10.0, 15.0):
        assert news(heard(t, None, {"cafe": 0.3})).left is None
        assert not news(decided(t, "cafe")).said


def test_silence_is_the_engines_own_mark_on_a_silent_windows_prediction():
    """The engine marks the prediction of a silent window (it asks no recogniser about it): an
    unsure window with no share for any place is not silence, nor is a notice the log sees."""
    news = LogNews()
    assert not news(heard(5.0, None, {"cafe": 0.0, "street": 0.0})).silent, "unsure, not silent"
    silent = AcousticPrediction(10.0, None, 0.0, {"cafe": 0.0, "street": 0.0}, "%", silent=True)
    assert news(silent).silent
    news(Notice(12.0, "arm stays put: cafe is only 40 % sure"))
    assert not news(heard(15.0, None, {"cafe": 0.2, "street": 0.1})).silent
    news = LogNews()
    news(heard(5.0, "cafe", CAFE))
    news(decided(5.0, "cafe"))
    assert news(AcousticPrediction(10.0, None, 0.0, {"cafe": 0.0}, "%", silent=True)) == News(
        True, silent=True, left="cafe"
    )
