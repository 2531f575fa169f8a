"""The Scene pane says what a decision's figure is: the probability of this place and not
somewhere else (a sound that knows elsewhere), or the senses' average (the rule policies)."""

from __future__ import annotations

from servant_core.events import AcousticPrediction, Decision, UnknownScene, VisualPrediction
from servant_tui.widgets.scene import ScenePane


def rows_text(decision: Decision) -> list[str]:
    pane = ScenePane()
    pane.decisions.appendleft(decision)
    return [str(text) for _, _, text in pane._rows()]


def test_a_decision_that_knows_elsewhere_says_so() -> None:
    sure = Decision(5.0, "cafe", 81.0, "CafeScene detected", 90.0, 50.0, "%", not_elsewhere=True)
    assert "here, not elsewhere 81.0 %" in rows_text(sure)
    averaged = Decision(5.0, "cafe", 70.0, "CafeScene detected", 90.0, 50.0, "%")
    assert "average 70.0 %" in rows_text(averaged)


def test_at_an_untaught_place_the_pane_says_so_and_the_last_decision_is_history() -> None:
    """Walked on from the café to a building site: once "What is this place?" is asked, the
    Scene pane no longer shows the café as what was decided; once the sound names a taught place
    again it is deciding, the café still history, until the next decision."""
    pane = ScenePane()
    cafe = Decision(5.0, "cafe", 81.0, "CafeScene detected", 90.0, 50.0, "%", not_elsewhere=True)
    pane.show_event(cafe)
    decided = dict((key, str(text)) for key, _, text in pane._rows())["decided"]
    assert decided == "CafeScene detected"

    pane.show_event(UnknownScene(60.0, "audio", "cafe", "w1"))
    rows = [(key, str(text)) for key, _, text in pane._rows()]
    assert ("decided", "an unknown place") in rows
    assert any(key == "history" and text.startswith("cafe") for key, text in rows)
    # a picture naming a place does not answer a question about the sound
    pane.show_event(VisualPrediction(62.0, "cafe", 60.0, confidence_unit="%"))
    assert ("decided", "an unknown place") in [(k, str(t)) for k, _, t in pane._rows()]

    pane.show_event(AcousticPrediction(65.0, "street", 70.0, confidence_unit="%"))
    rows = [(key, str(text)) for key, _, text in pane._rows()]
    assert ("decided", "deciding…") in rows
    assert ("decided", "CafeScene detected") not in rows
    assert any(key == "history" and text.startswith("cafe") for key, text in rows)

    street = Decision(70.0, "street", 75.0, "StreetScene detected", 80.0, 70.0, "%")
    pane.show_event(street)
    rows = [(key, str(text)) for key, _, text in pane._rows()]
    assert ("decided", "StreetScene detected") in rows
    assert [text[:6] for key, text in rows if key == "history"] == ["cafe  "]


def test_when_the_sound_stops_naming_the_place_decided_the_pane_says_so_as_the_log_does() -> None:
    """Left the café into silence: the log says `No scene detected (cafe no longer heard:
    silence)` at once; the pane said `CafeScene detected` until the next decision. It now says
    what the log says, the café goes to the history, and the next decision replaces it."""
    pane = ScenePane()
    pane.show_event(AcousticPrediction(0.0, "cafe", 95.0, confidence_unit="%"))
    cafe = Decision(5.0, "cafe", 81.0, "CafeScene detected", 90.0, 50.0, "%", not_elsewhere=True)
    pane.show_event(cafe)
    pane.show_event(AcousticPrediction(10.0, None, 0.0, silent=True))
    rows = [(key, str(text)) for key, _, text in pane._rows()]
    assert ("decided", "No scene detected") in rows
    assert ("average", "cafe no longer heard: silence") in rows
    assert any(key == "history" and text.startswith("cafe") for key, text in rows)

    # the policy's own "none" afterwards keeps the why; only a place decided again replaces it
    pane.show_event(Decision(20.0, None, 0.0, "No scene detected"))
    assert ("average", "cafe no longer heard: silence") in [(k, str(t)) for k, _, t in pane._rows()]
    pane.show_event(AcousticPrediction(25.0, "cafe", 95.0, confidence_unit="%"))
    pane.show_event(Decision(30.0, "cafe", 82.0, "CafeScene detected", 90.0, 50.0, "%"))
    rows = [(key, str(text)) for key, _, text in pane._rows()]
    assert ("decided", "CafeScene detected") in rows
    assert not any("no longer heard" in text for _, text in rows)


def test_leaving_for_an_unknown_place_says_so_without_a_question_yet() -> None:
    pane = ScenePane()
    pane.show_event(AcousticPrediction(0.0, "cafe", 95.0, confidence_unit="%"))
    pane.show_event(Decision(5.0, "cafe", 81.0, "CafeScene detected", 90.0, 50.0, "%"))
    pane.show_event(AcousticPrediction(10.0, None, 0.0, confidence_unit="%"))
    rows = [(key, str(text)) for key, _, text in pane._rows()]
    assert ("average", "cafe no longer heard: an unknown place") in rows
