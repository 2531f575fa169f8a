"""Shared fixtures: where the real data is, and small scene libraries built from it."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

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


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own hook reads the groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """`make test` runs the suite on two workers (`-n 2 --dist loadgroup`): a file's tests stay
    together on one worker (some share a fixed path, such as the snapshots' library), and the
    files of `ONE_MICROPHONE` share one worker. Those need the virtual microphone: `devices`."""
    for item in items:
        name = item.path.name
        item.add_marker(pytest.mark.xdist_group("microphone" if name in ONE_MICROPHONE else name))
        if name in ONE_MICROPHONE:
            item.add_marker(pytest.mark.devices)


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
