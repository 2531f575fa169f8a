"""The app asks of an engine what `EngineLike` lists, no more: mypy checks that the real engine
is one (`servant_tui.main` hands `Engine`s to the app), and this that the tests' replay is one
too, so that the TUI tests run the app over an engine it could be given."""

from servant_core.engine import Engine
from servant_tui.app import EngineLike
from tests.tui_replay import ReplayEngine


def test_the_engine_and_the_replay_have_all_the_app_asks_for():
    assert isinstance(Engine(), EngineLike)
    assert isinstance(ReplayEngine(), EngineLike)


def test_an_engine_without_one_of_them_is_not_engine_like():
    class Partial(ReplayEngine):
        read_arm_pose = None  # type: ignore[assignment]

    replay = ReplayEngine()
    del replay.model_path
    assert not isinstance(replay, EngineLike)
    assert not isinstance(Partial(), EngineLike)
