"""What the Scene pane says of the camera's pictures, on screen, with a model taught six real
pictures a place (issue 38: an hour of live use showed every picture as `1.0× average`, so the
camera never changed a decision).

The real live engine (`build_live_engine`, as `servant` builds it) with a model trained as
`servant train` trains it on a café and a street (real recordings, six real photographs each),
a video file of other photographs of one place as its camera, and the app's Scene pane read as
the user reads it (the pane rendered to text)."""

from __future__ import annotations

import html
import re

import pytest

from servant_core.cli import main as cli_main
from servant_core.engine import LiveSettings, build_live_engine
from servant_tui.app import ServantApp
from tests.conftest import link_library
from tests.test_cli_recognition import TWO_PLACES
from tests.test_live_path import picture_video
from tests.test_tui_live import settle

# the Scene pane's row (the log's lines read "sees cafe (2.0× average)")
SEES = re.compile(r"sees\s+(\w+)\s+([\d.]+)× average")
# the pane's count of the pictures taken in the fusion's window
PICTURES = re.compile(r"pictures\s*(\d+)")


def screen_text(app: ServantApp) -> str:
    """The terminal's text as the user sees it (the screenshot's SVG, tags and styles gone)."""
    svg = app.export_screenshot()
    return html.unescape(re.sub(r"<[^>]+>", "", svg)).replace("\xa0", " ")


@pytest.fixture(scope="module")
def taught_model(tmp_path_factory, shared_data):
    root = tmp_path_factory.mktemp("taught")
    library = link_library(root / "library", shared_data, TWO_PLACES)
    model = root / "model.npz"
    assert cli_main(["train", str(library), "-o", str(model)]) == 0
    return model


@pytest.mark.slow
@pytest.mark.parametrize("place", ["cafe", "street"])
async def test_pictures_of_a_taught_kind_read_clearly_above_average_on_screen(
    tmp_path, shared_data, taught_model, place
):
    others = sorted((shared_data / "images" / "dev" / place).glob("*.jpg"))[6:14]  # not taught
    video = picture_video(others, tmp_path / f"{place}.avi")
    engine = build_live_engine(
        LiveSettings(model=taught_model, use_microphone=False, camera=str(video))
    )
    app = ServantApp(engine, library_root=tmp_path / "library")
    seen: list[tuple[str, float]] = []
    counts: list[int] = []
    async with app.run_test(size=(120, 40)) as pilot:

        def three_pictures_shown() -> bool:
            # a reading for each picture taken: the "pictures" row counts them (two pictures
            # may read alike, "2.0× average" at two places, so the figure cannot tell them apart)
            text = screen_text(app)
            found, taken = SEES.search(text), PICTURES.search(text)
            if found and taken and (not counts or int(taken[1]) != counts[-1]):
                counts.append(int(taken[1]))
                seen.append((found[1], float(found[2])))
            return len(seen) >= 3

        await settle(pilot, three_pictures_shown, tries=2500)
    figures = [figure for scene, figure in seen if scene == place]
    assert len(figures) >= 2, seen  # most of its pictures name the place
    assert sorted(figures)[len(figures) // 2] >= 1.3, seen  # clearly likelier than average
