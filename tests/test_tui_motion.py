"""The motion pane and the sample senses on the live screen: the acceleration trace, each sense's
judgement in the motion and scene panes and the log, the senses a decision leaned on, the line
without a motion sensor, and sensor frames that replace one another when they flood."""

from __future__ import annotations

import io

import numpy as np
from rich.console import Console

from servant_core.engine import ManualClock, build_demo_engine
from servant_core.events import DeviceStatus, SensePrediction
from servant_tui.app import ServantApp
from servant_tui.messages import SensorUpdate, SpectrumUpdate
from servant_tui.widgets.motion import (
    NO_MOTION,
    acceleration_magnitude,
    block_rows,
    column_means,
)
from tests.test_tui_live import log_text, settle
from tests.tui_replay import (
    ReplayEngine,
    ambient_frame,
    sensing_script,
    spectrum_frame,
    walking_frame,
)


def plain(widget) -> str:
    """What a Static shows, as text at its width (a table's rows, one per line)."""
    console = Console(width=widget.size.width or 80, file=io.StringIO(), record=True)
    console.print(widget.content)
    return "\n".join(line.rstrip() for line in console.export_text().splitlines())


def test_acceleration_magnitude_takes_the_named_axes():
    rows = np.array([[0.0, 3.0, 4.0, 9.0], [1.0, 0.0, 0.0, 9.0]])
    assert acceleration_magnitude(rows, ("gx", "ax", "ay", "az")).tolist() == [
        np.sqrt(9 + 16 + 81),
        9.0,
    ]
    assert acceleration_magnitude(rows[:, :3], ()).tolist() == [5.0, 1.0]


def test_column_means_average_each_stretch_and_grow_from_the_right():
    assert column_means(np.arange(8.0), 4, 8).tolist() == [0.5, 2.5, 4.5, 6.5]
    # half the span read so far: the left half of the trace is empty, the right at full scale
    half = column_means(np.array([2.0, 4.0]), 4, 4)
    assert np.isnan(half[:2]).all() and half[2:].tolist() == [2.0, 4.0]
    # more columns than readings: every column shows the reading it falls on
    assert column_means(np.array([1.0, 3.0]), 4, 2).tolist() == [1.0, 1.0, 3.0, 3.0]
    # only the last `span` readings count
    assert column_means(np.array([100.0, 1.0, 3.0]), 2, 2).tolist() == [1.0, 3.0]


def test_block_rows_fill_from_the_bottom_in_eighths():
    assert block_rows(np.array([0.0, 0.5, 1.0, np.nan, 9 / 16]), 2) == [
        "  █ ▁",
        " ██ █",
    ]


def test_a_newer_sensor_frame_replaces_a_queued_one_of_the_same_sense_only():
    motion, later = SensorUpdate(walking_frame(1.0)), SensorUpdate(walking_frame(1.2))
    assert motion.can_replace(later)
    assert not motion.can_replace(SensorUpdate(ambient_frame(1.2)))
    assert not motion.can_replace(SpectrumUpdate(spectrum_frame(1.2)))
    assert not SpectrumUpdate(spectrum_frame(1.0)).can_replace(later)


async def test_the_motion_pane_traces_the_walk_and_says_what_each_sense_judged(tmp_path):
    engine = ReplayEngine(sensing_script())
    app = ServantApp(engine, mode="demo", library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, lambda: len(app.live.scene.decisions) == 3)
        await pilot.pause()
        motion = app.live.motion
        assert motion.trace.display and motion.trace.frames_shown == 1
        trace = [strip.text for strip in motion.trace._strips]
        assert trace[0].startswith(" 20┤") and trace[-1].startswith("  0┤")
        # the walk's bounce: gravity fills half the scale, the steps wiggle above it
        bottom, top = trace[-1][4:], "".join(trace[:-1])
        assert set(bottom) == {"█"} and set(top) - {" ", "│", "┤", "2", "0"}
        assert plain(motion.said) == "motion street 77.0 % · ambient CoffeeScene 91.0 %"
        assert plain(motion.values) == "312 lx 21.5 °C 1013 hPa"

        scene = plain(app.live.scene)
        assert "motion   street        77.0 %" in scene
        assert "ambient  CoffeeScene   91.0 %" in scene
        assert "leaned   on sound, motion" in scene
        log = log_text(app)
        assert "motion: street (77.0%)" in log and "ambient: CoffeeScene (91.0%)" in log
        # the café decided again, now leaning on sound and motion: the Scene pane says so (above);
        # the log said the café's decision once (servant_core.log_news: a line when it changes)
        assert log.count("CoffeeScene detected") == 1
        assert "CoffeeScene detected (90.1%" not in log

        # a place the ambient sense does not know: no confidence in no scene
        engine.emit(SensePrediction(60.0, "ambient", None, 100.0, {}, "%"))
        await settle(pilot, lambda: "unknown" in plain(motion.said))
        assert plain(motion.said) == "motion street 77.0 % · ambient an unknown place"
        await settle(pilot, lambda: "ambient  unknown place" in plain(app.live.scene))
        assert "100.0" not in plain(app.live.scene)  # nor in the scene pane

        # the board unplugged: said on the pane, in red, until it reads again
        engine.emit(DeviceStatus(61.0, "imu", False, "/dev/pts/4: the sensor board stopped"))
        await settle(pilot, lambda: "stopped" in plain(motion.values))
        assert (
            plain(motion.values) == "312 lx 21.5 °C 1013 hPa · /dev/pts/4: the sensor board stopped"
        )
        engine.emit(DeviceStatus(63.0, "imu", True, "/dev/pts/4: reading at 50 Hz"))
        await settle(pilot, lambda: "stopped" not in plain(motion.values))


async def test_without_sample_senses_the_pane_says_how_to_start_one(tmp_path):
    app = ServantApp(ReplayEngine(), mode="demo", library_root=tmp_path)
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(pilot, lambda: app.live.scene.decisions)
        motion = app.live.motion
        assert plain(motion.said) == NO_MOTION
        assert not motion.trace.display and not motion.values.display
        assert motion.region.height == 3, "one line between its borders"
        scene = plain(app.live.scene)
        assert "motion" not in scene and "ambient" not in scene and "leaned" not in scene


async def test_at_80x24_the_scene_pane_keeps_every_sense_and_the_decision(tmp_path):
    app = ServantApp(ReplayEngine(sensing_script()), mode="demo", library_root=tmp_path)
    async with app.run_test(size=(80, 24)) as pilot:
        await settle(pilot, lambda: len(app.live.scene.decisions) == 3)
        await pilot.pause()
        rows = [line.split()[0] for line in plain(app.live.scene).splitlines()]
        assert rows == ["hears", "sees", "motion", "ambient", "fusion", "decided", "leaned"]
        # the trace beside the spectrum, under the ambient values; judgements are in the scene
        assert app.live.motion.region.x > app.live.spectrum.region.x
        assert not app.live.motion.said.display
        assert app.live.motion.trace.region.height == 3  # the row the arm's protocol gave up


async def test_the_demo_engine_feeds_the_motion_pane(tmp_path):
    engine = build_demo_engine(
        seed=0, clock=ManualClock(), realtime=False, library_root=tmp_path, arm=False
    )
    said: list[SensePrediction] = []
    engine.subscribe(lambda e: said.append(e) if isinstance(e, SensePrediction) else None)
    app = ServantApp(engine, mode="demo")
    async with app.run_test(size=(100, 30)) as pilot:
        await settle(
            pilot,
            lambda: (
                {"motion", "ambient"} <= {e.sense for e in said}
                and app.live.motion.trace.frames_shown
            ),
            tries=1500,
        )
        await pilot.pause()
        motion = app.live.motion
        assert motion.senses == ["motion", "ambient"]
        assert "°C" in plain(motion.values) and "hPa" in plain(motion.values)
        assert "motion " in plain(motion.said) and "–" not in plain(motion.said)
        assert app.live.scene.felt["motion"] is not None
        assert "motion: " in log_text(app)
