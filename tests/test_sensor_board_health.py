"""A sensor board that stalls, sends only junk, or runs at another rate than its windows are
cut by: one status line each (issue 24, item 8), on the watch's own arithmetic and through the
engine on a real pty (the project's emulator at the wrong rate; a pty fed junk by the test)."""

from __future__ import annotations

import os
import threading
import time

import pytest

from servant_core.capture.sensor_sources import sensor_sources
from servant_core.demo.sensor_emulator import SensorEmulator, script_scene
from servant_core.engine import Engine
from servant_core.engine.stream_watch import STALL_SECONDS, StreamWatch
from servant_core.events import DeviceStatus, SensePrediction
from servant_core.modelfile import load_model
from servant_core.pty_port import PtyPort
from tests.test_sample_senses_engine import sensor_model as sensor_model  # a fixture


def test_a_stall_is_said_once_and_its_end_too():
    watch = StreamWatch("imu sensor on /dev/pts/9", 50, opened_at=0.0)
    assert watch.arrived(0.5, 25) is None
    assert watch.quiet(0.5 + STALL_SECONDS - 0.1) is None
    stalled = watch.quiet(0.5 + STALL_SECONDS)
    assert stalled is not None and not stalled.ok and "no reading for 3 s" in stalled.message
    assert watch.quiet(10.0) is None  # said once
    back = watch.arrived(11.0, 5)
    assert back is not None and back.ok and "reading at 50 Hz" in back.message


def test_junk_alone_is_named_as_junk():
    watch = StreamWatch("imu sensor on /dev/pts/9", 50, opened_at=0.0)
    news = watch.quiet(4.0, junk_lines=812)
    assert news is not None and "only 812 lines that are not readings" in news.message
    assert "baud rate" in news.message


@pytest.mark.parametrize("rate, off", [(50, False), (80, False), (1000, True), (10, True)])
def test_a_rate_off_by_more_than_twice_stops_the_readings_until_it_is_right(rate, off):
    watch = StreamWatch("imu", 50, opened_at=0.0)
    said = []
    t = 0.0
    for _ in range(100):  # 5 s in blocks of 50 ms
        t += 0.05
        said.append(watch.arrived(t, int(round(rate * 0.05)) or (1 if int(t * 20) % 5 == 0 else 0)))
    news = [n for n in said if n is not None]
    assert (not watch.usable) == off
    assert len(news) == (1 if off else 0)
    if off:
        assert not news[0].ok and "where 50 are expected" in news[0].message
        for _ in range(120):  # the sketch fixed: 50 a second for 6 s
            t += 0.05
            fixed = watch.arrived(t, 2 if int(t * 20) % 2 else 3)
            if fixed is not None:
                assert fixed.ok
        assert watch.usable


def statuses(events: list, device: str) -> list[DeviceStatus]:
    return [e for e in events if isinstance(e, DeviceStatus) and e.device == device]


def test_a_board_at_twenty_times_its_rate_is_said_and_its_flood_not_judged(sensor_model):
    """The emulator sends 1,000 readings a second (a sketch set to another rate); the engine
    cuts windows at 50: before, a flood like it gave 6,288 windows in 12 s."""
    emulator = SensorEmulator(script_scene([("street", 1000.0)]), seed=2, imu_rate=1000)
    port = emulator.start()
    engine = Engine(
        samples={"motion": sensor_sources({"imu": port})["imu"]},
        sample_recognisers=load_model(sensor_model),
    )
    events: list = []
    engine.subscribe(events.append)
    try:
        with engine:
            time.sleep(8.0)
    finally:
        emulator.stop()
    said = [s for s in statuses(events, "imu") if not s.ok]
    assert said and "readings a second arrive where 50 are expected" in said[0].message, said
    judged = [e for e in events if isinstance(e, SensePrediction)]
    assert len(judged) <= 4, len(judged)  # a second or so of flood before it was plain


def test_a_board_that_sends_only_junk_is_said_in_one_line():
    pty = PtyPort()
    stop = threading.Event()

    def babble() -> None:  # a board at another baud rate: bytes, never a reading
        while not stop.wait(0.02):
            os.write(pty.master, b"\xf0\x0f?~\x80 junk\n")

    engine = Engine(samples={"motion": sensor_sources({"imu": pty.port})["imu"]})
    events: list = []
    engine.subscribe(events.append)
    writer = threading.Thread(target=babble, daemon=True)
    writer.start()
    try:
        with engine:
            deadline = time.monotonic() + 15
            while not [s for s in statuses(events, "imu") if not s.ok]:
                assert time.monotonic() < deadline, events
                time.sleep(0.1)
    finally:
        stop.set()
        writer.join()
        pty.close()
    said = [s for s in statuses(events, "imu") if not s.ok]
    assert len(said) == 1 and "lines that are not readings" in said[0].message, said
