"""Words stay apart however the screen is read: a space between two differently styled words
belongs to the first word's run, so no run of text starts with the space. A reader that takes
each styled run on its own and trims it (screen readers, text pulled from an SVG screenshot) read
`00:00.0arm disarmed` and `lookingCoffeeScene` when the space started the second run."""

from __future__ import annotations

import html
import re
from collections import defaultdict

from servant_tui.app import ServantApp
from tests.test_tui_live import settle
from tests.tui_replay import ReplayEngine

TEXT = re.compile(r'<text [^>]*y="([\d.]+)"[^>]*>([^<]*)</text>')


async def test_no_styled_run_starts_with_the_space_before_its_word(tmp_path):
    app = ServantApp(ReplayEngine(), mode="demo", library_root=tmp_path)
    async with app.run_test(size=(160, 36)) as pilot:  # the decision on one row of the log
        await settle(pilot, lambda: app.live.scene.decisions)
        await pilot.pause()
        svg = app.export_screenshot()
    lines = "\n".join(read_trimming_runs(svg))
    assert "00:00.0 arm disarmed" in lines
    assert "looking CoffeeScene" in lines
    assert "CoffeeScene detected (87.5%)" in lines


def read_trimming_runs(svg: str) -> list[str]:
    """Each screen line read run by run (`<text>` elements), each run's leading spaces dropped."""
    lines: dict[str, str] = defaultdict(str)
    for y, run in TEXT.findall(svg):
        lines[y] += html.unescape(run).replace("\xa0", " ").lstrip()
    return list(lines.values())
