"""The arm named on `servant run`'s command line stays attached through the screens that read
the user's settings. (A wearer's whole first session, teach mode to the arm's pose, is typed
into a real terminal by `tests/test_readme_walk.py`.)"""

from __future__ import annotations

import pytest

from servant_core.cli.live import build_run_engine
from servant_core.servo.emulator import start_emulator
from servant_tui.app import ServantApp
from tests.test_tui_live import settle


async def wait(pilot, predicate, seconds: float) -> None:
    await settle(pilot, predicate, tries=int(seconds / 0.02))


@pytest.mark.timeout(120)
@pytest.mark.parametrize("screen", ["t", "s"])
async def test_the_arm_named_by_servant_run_port_stays_attached_after_teach_or_settings(
    tmp_path, screen
):
    """`servant run --port P` with an empty config dir: opening teach mode or the Settings
    screen (both read the user's settings) must not put the settings file's arm (none) in place
    of the one the command line named."""
    from servant_core.cli import build_parser

    emulator, port = start_emulator("maestro")
    args = build_parser().parse_args(["run", "--port", port, "--no-mic", "--no-camera"])
    engine = build_run_engine(args)
    app = ServantApp(engine)
    try:
        async with app.run_test(size=(120, 40)) as pilot:
            await wait(pilot, lambda: app.arm_state is not None and app.arm_state.connected, 20)
            await pilot.press(screen)
            await wait(pilot, lambda: app.screen is not app.live, 10)
            await pilot.pause(1.0)  # the settings reach the engine in a worker
            await pilot.press("escape")
            await wait(pilot, lambda: app.screen is app.live, 10)
            await pilot.pause(1.0)
            assert engine.status["servo"].ok, engine.status["servo"].message
            assert app.arm_state is not None and app.arm_state.connected
    finally:
        engine.stop()
        emulator.stop()
