"""The TUI over the real demo engine (synthesised scenes, paper recognisers, sequential fusion)."""

from __future__ import annotations

from servant_core.engine import ManualClock, build_demo_engine
from servant_tui.app import ServantApp
from tests.test_tui_live import log_text, settle


async def test_demo_engine_reaches_a_decision_in_the_log(tmp_path):
    # realtime=False: the synthesised walk plays as fast as the machine goes, on a simulated clock.
    engine = build_demo_engine(seed=0, clock=ManualClock(), realtime=False, library_root=tmp_path)
    app = ServantApp(engine, mode="demo")
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, lambda: app.live.scene.decisions, tries=1500)
        assert app.live.spectrum.frames_shown > 0
        assert "detected" in log_text(app)
        assert app.library_root == tmp_path
        # the demo's emulated arm, attached before the app subscribed, is known and can be armed
        assert app.arm_state is not None and app.arm_state.connected and not app.arm_state.armed
        assert app.check_action("toggle_arm", ()) is True
        await pilot.press("a")
        await settle(pilot, lambda: app.arm_state.armed)
    assert not engine.running, "quitting stops the engine's threads"


async def test_the_demos_log_says_why_its_senses_disagree_on_the_street(tmp_path):
    """Issue 39 item 2, in the application: `hears street`, `sees coffee` for 35 s, then
    `No scene detected`, and nothing on the screen said why. The log says each stretch of the
    walk as it begins, the disagreement with its reason, before that `No scene detected`."""
    engine = build_demo_engine(seed=0, clock=ManualClock(), realtime=False, library_root=tmp_path)
    app = ServantApp(engine, mode="demo")
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, lambda: "StreetScene detected" in log_text(app), tries=3000)
        said = log_text(app)
    assert "demo walk: in the coffee shop" in said, said
    disagree = said.index("demo walk: outside, still looking into the café: sound and sight")
    assert disagree < said.index("No scene detected") < said.index("StreetScene detected"), said
