"""`servant demo` in a real terminal: tmux runs it, `capture-pane` reads the screen."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytestmark = [
    pytest.mark.devices,
    pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed"),
]


def servant_command() -> str:
    """The installed `servant` script when it is on PATH (CI), else this interpreter's module."""
    script = shutil.which("servant")
    return script if script else f"{sys.executable} -m servant_tui"


def capture(session: str) -> str:
    return subprocess.run(
        ["tmux", "capture-pane", "-p", "-t", session], capture_output=True, text=True, check=True
    ).stdout


def test_servant_demo_shows_panes_and_a_detection_in_tmux(tmp_path):
    session = f"servant-{uuid.uuid4().hex[:8]}"
    env = {
        **os.environ,
        "SERVANT_DATA_DIR": str(tmp_path / "data"),
        "SERVANT_CONFIG_DIR": str(tmp_path / "config"),
    }
    command = f"cd {ROOT} && exec {servant_command()} demo"
    subprocess.run(
        ["tmux", "new-session", "-d", "-s", session, "-x", "160", "-y", "48", command],
        check=True,
        env=env,
    )
    try:
        screen = ""
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            time.sleep(1.0)
            screen = capture(session)
            if "detected" in screen:
                break
        for title in ("Spectrum", "Motion", "Scene", "Colours", "Arm", "Log"):
            assert title in screen, f"pane {title!r} missing from the terminal:\n{screen}"
        assert "detected" in screen, f"no detection line after 120 s:\n{screen}"
        subprocess.run(["tmux", "send-keys", "-t", session, "q"], check=True)
        for _ in range(20):
            time.sleep(0.5)
            alive = subprocess.run(["tmux", "has-session", "-t", session], capture_output=True)
            if alive.returncode != 0:
                break
        assert alive.returncode != 0, "q did not quit servant demo"
    finally:
        subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)
