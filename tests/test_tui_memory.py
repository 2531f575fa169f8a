"""What made the TUI's memory grow for most of an hour (issue 13; `bench/soak.py` measures it):
the log kept more lines cached than it keeps, and every new camera colour filled Rich's caches."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rich.style import Style
from textual.app import App

import servant_tui
from servant_core.events import Palette
from servant_tui.screens.live import LiveScreen
from servant_tui.widgets.colours import swatch_colour


class LiveOnly(App[None]):
    """The live screen, with the application's layout, and no engine."""

    CSS_PATH = str(Path(servant_tui.__file__).parent / "app.tcss")

    def get_default_screen(self) -> Any:
        return LiveScreen()


async def test_the_log_caches_no_more_lines_than_it_keeps():
    app = LiveOnly()
    async with app.run_test(size=(160, 48)) as pilot:
        screen = app.screen
        for batch in range(50):  # a thousand lines, drawn twenty at a time
            for i in range(20):
                screen.write_log(f"[dim]{batch:02d}:{i:02d} [/]sees coffee ({i}.5 %)")
            await pilot.pause()
        log = screen.log_view
        assert len(log.lines) < 1000  # bounded
        # RichLog's private cache of drawn lines: it held every line drawn, 1,024 at most, long
        # after the log had dropped them
        assert len(log._line_cache) <= len(log.lines)


async def test_new_camera_colours_are_not_parsed_into_richs_caches():
    app = LiveOnly()
    rng = np.random.default_rng(0)
    async with app.run_test(size=(160, 48)) as pilot:
        screen = app.screen
        parsed = Style.parse.cache_info().currsize
        for i in range(100):  # every picture brings three colours never seen before
            colours = rng.integers(0, 256, (3, 3)).astype(np.uint8)
            screen.show_event(Palette(float(i), colours, np.array([0.5, 0.3, 0.2]), "coffee"))
            await pilot.pause()
        assert Style.parse.cache_info().currsize - parsed < 10


def test_swatches_are_drawn_in_sixteen_levels_a_channel():
    assert swatch_colour(np.array([0, 8, 9], np.uint8)).get_truecolor() == (0, 0, 17)
    assert swatch_colour(np.array([255, 247, 127], np.uint8)).get_truecolor() == (255, 255, 119)
    levels = {
        swatch_colour(rgb).get_truecolor()
        for rgb in np.random.default_rng(1).integers(0, 256, (2000, 3))
    }
    assert all(v % 17 == 0 for rgb in levels for v in rgb)


RELEASE_SCRIPT = """
import numpy as np
from pathlib import Path
from servant_tui.heap import release_free_heap

def rss_mb():
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024

big = np.ones(2**21)  # 16 MiB, mapped on its own; freeing it raises glibc's threshold to that
del big
arrays, kept = [], []
for _ in range(6):  # 6 x 8 MiB now from the heap, each followed by a small array that stays
    arrays.append(np.ones(2**20))
    kept.append(np.ones(100))
del arrays
before = rss_mb()
release_free_heap()
print(before - rss_mb())
"""


def test_release_free_heap_gives_the_heaps_free_memory_back():
    """What a retrain leaves behind: large arrays freed inside the heap stay resident until the
    heap is trimmed (glibc; elsewhere `release_free_heap` does nothing and this is skipped)."""
    import ctypes.util
    import subprocess
    import sys

    if "libc.so.6" not in (ctypes.util.find_library("c") or ""):
        pytest.skip("not glibc")
    result = subprocess.run(
        [sys.executable, "-c", RELEASE_SCRIPT], capture_output=True, text=True, check=True
    )
    assert float(result.stdout) > 8  # MB given back (of 48 freed; 0 without the trim)


async def test_the_running_app_gives_free_heap_back_on_a_timer(tmp_path, monkeypatch):
    """A dialog left open makes every engine event redraw the whole screen, and glibc keeps the
    freed pages in its heaps for good (issue 13's soak): the app trims them on a timer, not only
    after a retrain. The trim itself is proven above; here a counter stands in for it."""
    import servant_tui.app as app_module
    from servant_tui.app import ServantApp
    from tests.tui_replay import ReplayEngine

    trims: list[float] = []
    monkeypatch.setattr(app_module, "HEAP_TRIM_EVERY_S", 0.05)
    monkeypatch.setattr(app_module, "release_free_heap", lambda: trims.append(0.0))
    app = ServantApp(ReplayEngine(), library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        for _ in range(100):
            if len(trims) >= 3:
                break
            await pilot.pause(0.05)
    assert len(trims) >= 3


ARENAS_SCRIPT = """
import ctypes, sys, threading
import numpy as np
from servant_tui.heap import limit_heaps

if sys.argv[1] == "limit":
    limit_heaps(2)
together = threading.Barrier(6)
kept = []

def allocate():
    together.wait()  # six threads alive at once: each would get a heap of its own
    kept.append([np.ones(1000) for _ in range(100)])  # 8 KB arrays: from the thread's heap
    together.wait()

threads = [threading.Thread(target=allocate) for _ in range(6)]
for thread in threads:
    thread.start()
for thread in threads:
    thread.join()
ctypes.CDLL("libc.so.6").malloc_stats()  # one "Arena N:" block per heap, on stderr
"""


@pytest.mark.parametrize(("mode", "most"), [("limit", 2), ("none", 16)])
def test_threads_share_two_heaps_once_limited(mode, most):
    """The app's threads share two C heaps (`limit_heaps`, called first thing by `servant`):
    by default glibc gives each new thread its own, and keeps what each frees (issue 13)."""
    import ctypes.util
    import subprocess
    import sys

    if "libc.so.6" not in (ctypes.util.find_library("c") or ""):
        pytest.skip("not glibc")
    result = subprocess.run(
        [sys.executable, "-c", ARENAS_SCRIPT, mode], capture_output=True, text=True, check=True
    )
    heaps = sum(line.startswith("Arena ") for line in result.stderr.splitlines())
    assert 1 <= heaps <= most
    if mode == "none":
        assert heaps > 2  # the default the limit changes (so the limited case can fail)
