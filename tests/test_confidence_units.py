"""A confidence is shown with what it is: "%" only for a probability in percent (`codebook`,
`bovw`); the paper's eq. 1 and eq. 2, which are no percentages and go far below zero on real
audio, with the equation's name."""

from __future__ import annotations

import numpy as np
from textual.geometry import Region

from servant_core.engine import decision_unit
from servant_core.event_text import confidence_text
from servant_core.events import AcousticPrediction, Decision, VisualPrediction
from servant_core.recognisers import ACOUSTIC_METHODS, VISUAL_METHODS
from servant_tui.app import ServantApp
from tests.test_tui_live import log_text, settle
from tests.tui_replay import ReplayEngine


def test_each_method_names_the_unit_of_its_confidence():
    assert ACOUSTIC_METHODS["paper"].confidence_unit == "eq. 1"
    assert VISUAL_METHODS["paper"].confidence_unit == "eq. 2"
    assert ACOUSTIC_METHODS["codebook"].confidence_unit == "%"
    assert VISUAL_METHODS["bovw"].confidence_unit == "%"


def test_confidence_text_says_the_unit_when_it_is_known():
    assert confidence_text(-6433.994, "eq. 1") == "-6434.0 eq. 1"
    assert confidence_text(88.04, "%", width=5) == " 88.0 %"
    assert confidence_text(88.04, None) == "88.0"


def test_a_decision_has_a_unit_only_when_both_senses_share_it():
    codebook, bovw = ACOUSTIC_METHODS["codebook"](), VISUAL_METHODS["bovw"]()
    paper_heard, paper_seen = ACOUSTIC_METHODS["paper"](), VISUAL_METHODS["paper"]()
    assert decision_unit(codebook, bovw) == "%"
    assert decision_unit(paper_heard, paper_seen) is None
    assert decision_unit(paper_heard, bovw) is None
    assert decision_unit(codebook, None) is None


def paper_script() -> list:
    return [
        AcousticPrediction(5.0, "street", -6433.994, {"street": 0.7}, "eq. 1"),
        VisualPrediction(7.0, "street", 36.9, {"street": 0.6}, "eq. 2"),
        Decision(9.0, "street", -3198.547, "StreetScene detected", -6433.994, 36.9),
    ]


async def test_paper_confidences_are_shown_with_their_equation_and_no_percent(tmp_path):
    app = ServantApp(ReplayEngine(paper_script()), library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, lambda: app.live.scene.decisions)
        await pilot.pause()
        pane = app.live.scene
        shown = "\n".join(strip.text for strip in pane.render_lines(Region(0, 0, *pane.outer_size)))
        log = log_text(app)
    assert "street -6434.0 eq. 1" in shown  # whole, in the narrowest layout
    assert "36.9 eq. 2" in shown
    assert "average -3198.5" in shown
    assert "%" not in shown
    assert "hears street (-6434.0 eq. 1)" in log and "sees street (36.9 eq. 2)" in log
    assert "StreetScene detected (-3198.5)" in log
    assert "%" not in log


def test_servant_predict_says_each_confidences_unit(tmp_path, capsys):
    """`servant predict` printed `confidence -24903.178`, a number a reader cannot place."""
    from servant_core.audio import write_wav
    from servant_core.cli import main
    from servant_core.demo.audio_synth import DEMO_RATE
    from servant_core.demo.scenes import synth_window, write_demo_library

    library = write_demo_library(tmp_path / "library")
    clip = write_wav(
        tmp_path / "clip.wav", synth_window("gym", np.random.default_rng(5)), DEMO_RATE
    )
    for method, unit in (("paper", "eq. 1"), ("codebook", "%")):
        model = tmp_path / f"{method}.npz"
        argv = ["train", str(library), "-o", str(model), "--audio-method", method]
        assert main([*argv, "--rate", str(DEMO_RATE)]) == 0
        capsys.readouterr()
        assert main(["predict", str(model), "--audio", str(clip)]) == 0
        line = capsys.readouterr().out.strip().splitlines()[0]
        assert line.startswith("Acoustic window 0 (0-5 s): ") and line.endswith(f" {unit})"), line
