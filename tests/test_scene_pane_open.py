"""The Scene pane says what a decision's figure is: the probability of this place and not
somewhere else (a sound that knows elsewhere), or the senses' average (the rule policies)."""

from __future__ import annotations

from servant_core.events import Decision
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
