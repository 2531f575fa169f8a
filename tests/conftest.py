"""Shared fixtures: where the real data is, and small scene libraries built from it."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from functools import cache
from pathlib import Path
from typing import Any

from servant_core.threads import one_thread_pools

one_thread_pools()  # as in the `servant` command, before numpy loads: the engines tested here too

import numpy as np  # noqa: E402
import pytest  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
# The files whose tests play into the virtual microphone's one null sink, or listen to it: under
# pytest-xdist they run on one worker, one at a time, so no test hears another's sound.
ONE_MICROPHONE = {
    "test_live_path.py",
    "test_microphone.py",
    "test_readme_walk.py",
    "test_tui_settings_devices.py",
}
# `make test-fast` leaves out the integration tests, which `make test` runs all the same: the
# generated-case suites, files whole, and single tests that fit whole models through the command
# line, walk the demo for minutes of simulated time, or wait on an emulated device in real time.
INTEGRATION_FILES = {
    "test_fuzz_files.py": "some 3,300 generated files through the command line",
    "test_fuzz_hardening.py": "some 2,000 generated cases through the command line",
    "test_fuzz_options.py": "some 2,000 generated option values through the parser",
    "test_fuzz_serial.py": "random replies to a servo link, through pyserial on a pty",
    "test_fuzz_settings.py": "generated settings and teach record files",
    "test_arm_properties.py": "100 random command streams to the servo emulator on a pty",
}
INTEGRATION_TESTS = {
    "test_eval_protocols.py": {
        "test_eval_audio_follows_every_fold_after_the_listening",  # 24 models: 12 folds, 2 seeds
    },
    "test_demo_scenes.py": {
        "test_walk_is_deterministic_and_shows_detections_mismatch_and_no_scene",  # 100 s, twice
        "test_paper_demo_detects_every_scene_in_every_loop",  # three rounds, three times
    },
    "test_engine.py": {
        # the fresh methods fitted on a library, then all of it replayed
        "test_a_first_retrain_without_recognisers_fits_fresh_ones_and_saves_them",
    },
    "test_confidence_units.py": {
        "test_servant_predict_says_each_confidences_unit",  # two models trained, as by `servant`
    },
    "test_sensor_board_health.py": {
        "test_a_board_at_twenty_times_its_rate_is_said_and_its_flood_not_judged",  # 8 s of flood
    },
    "test_tui_teach_senses.py": {
        # two 5 s recordings in real time, from an emulated sensor board
        "test_teach_writes_motion_and_ambient_beside_the_sound_and_keeps_the_sound_when_the_board_stops",  # noqa: E501
    },
    "test_sample_senses_engine.py": {
        # the demo's engine in real time until its board's first window
        "test_the_demos_sensor_board_starts_with_the_walk_not_when_the_demo_is_built",
    },
}
# `servant` in a child process, as `devices` says, though not in a file of ONE_MICROPHONE.
CHILD_PROCESS_TESTS = {
    ("test_headless_lines.py", "test_the_demo_says_why_its_senses_disagree_on_the_street"),
}


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own hook reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """`make test` runs the suite on two workers (`-n 2 --dist loadgroup`): a file's tests stay
    together on one worker (some share a fixed path, such as the snapshots' library), and the
    files of `ONE_MICROPHONE` share one worker. Those need the virtual microphone: `devices`.
    A test reading the real data (the `shared_data` fixture) is `slow`; the tests of
    `INTEGRATION_FILES` and `INTEGRATION_TESTS` are `integration`."""
    for item in items:
        name = item.path.name
        test = (name, getattr(item, "originalname", item.name))
        item.add_marker(pytest.mark.xdist_group("microphone" if name in ONE_MICROPHONE else name))
        if name in ONE_MICROPHONE or test in CHILD_PROCESS_TESTS:
            item.add_marker(pytest.mark.devices)
        if "shared_data" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.slow)
        if name in INTEGRATION_FILES or test[1] in INTEGRATION_TESTS.get(name, ()):
            item.add_marker(pytest.mark.integration)


def shared_data_dir() -> Path | None:
    """`../shared/data` beside the repository, or $SERVANT_SHARED_DATA."""
    candidates = [os.environ.get("SERVANT_SHARED_DATA"), REPO.parent / "shared" / "data"]
    for candidate in candidates:
        if candidate and Path(candidate, "audio", "dev").is_dir():
            return Path(candidate)
    return None


@pytest.fixture(scope="session")
def shared_data() -> Path:
    found = shared_data_dir()
    if found is None:
        pytest.skip("the real data (../shared/data or $SERVANT_SHARED_DATA) is not on this machine")
    return found


@pytest.fixture(autouse=True)
def _private_dirs(
    tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Keep every test away from the user's real data and config directories."""
    base = tmp_path_factory.mktemp("servant-home")
    monkeypatch.setenv("SERVANT_DATA_DIR", str(base / "data"))
    monkeypatch.setenv("SERVANT_CONFIG_DIR", str(base / "config"))
    monkeypatch.setenv("SERVANT_RUNTIME_DIR", str(base / "run"))


@cache
def demo_recognisers(paper: bool) -> tuple[Any, Any]:
    """The demo's sound and picture recognisers of seed 0 (`paper`: the paper's), trained once a
    worker: tests only read them, and the engine folds a label into a copy, never into them."""
    from servant_core.demo.scenes import train_demo_recognisers

    return train_demo_recognisers(seed=0, paper=paper)


def link_library(root: Path, shared: Path, scenes: dict[str, tuple[list[str], int]]) -> Path:
    """A scene library of symbolic links into the real data (nothing is copied):
    scenes maps scene -> (recording file names, number of pictures taken by file order)."""
    for scene, (recordings, n_pictures) in scenes.items():
        folder = root / scene
        folder.mkdir(parents=True, exist_ok=True)
        for name in recordings:
            (folder / name).symlink_to(shared / "audio" / "dev" / scene / name)
        pictures = sorted((shared / "images" / "dev" / scene).glob("*.jpg"))[:n_pictures]
        for picture in pictures:
            (folder / picture.name).symlink_to(picture)
    return root


def tone(freq: float, seconds: float, rate: int, amplitude: float = 0.5) -> np.ndarray:
    t = np.arange(int(round(seconds * rate))) / rate
    return (amplitude * np.sin(2 * np.pi * freq * t)).astype(np.float32)


def servant(*args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
    """`servant ARGS` in a child process, as a user runs it (output captured)."""
    return subprocess.run(
        [sys.executable, "-m", "servant_tui", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        timeout=120,
    )


def ctrl_c_as_in_a_terminal() -> None:
    """In a child, before Python starts: Ctrl-C as a terminal delivers it. Tests started in the
    background by a non-interactive shell (`make test &`) inherit SIGINT ignored, and a Python
    started so never sees Ctrl-C at all: a test sending it would fail, saying nothing of
    Servant."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def serve(*args: str) -> tuple[subprocess.Popen[str], str]:
    """`servant ARGS` (an emulator) in its own process, and the port its first line names
    ("… on PORT; …" or "… on PORT …"); the caller stops the process (Ctrl-C reaches it as in a
    terminal)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "servant_tui", *args],
        stdout=subprocess.PIPE,
        text=True,
        cwd=REPO,
        preexec_fn=ctrl_c_as_in_a_terminal,
    )
    assert proc.stdout is not None
    first = proc.stdout.readline()
    found = re.search(r" on (\S+?);? ", first)
    if found is None:
        proc.kill()
        proc.wait()
        raise AssertionError(f"servant {' '.join(args)} named no port: {first!r}")
    return proc, found.group(1)
