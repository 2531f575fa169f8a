"""Issue 22 item 1: after `make install`, `servant` is a command in a new shell, and the README
says so in its first lines."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")


@pytest.mark.devices
def test_make_install_puts_servant_on_the_path(tmp_path):
    venv = Path(sys.prefix)  # the env these tests run in: `make setup` is not run again
    bindir = tmp_path / "bin"
    env = {**os.environ, "PATH": "/usr/bin:/bin"}
    made = subprocess.run(
        ["make", "-C", str(REPO), "-o", f"{venv}/.installed", "install"]
        + [f"VENV={venv}", f"BINDIR={bindir}"],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
    )
    assert made.returncode == 0, made.stderr
    assert f'export PATH="{bindir}:$PATH"' in made.stdout  # not on PATH yet: says what to add
    shell = {**env, "PATH": f"{bindir}:/usr/bin:/bin"}
    found = shutil.which("servant", path=shell["PATH"])
    assert found == str(bindir / "servant")
    result = subprocess.run(
        ["servant", "--help"], capture_output=True, text=True, env=shell, timeout=60
    )
    assert result.returncode == 0 and "train" in result.stdout, result.stderr


def test_the_readme_says_how_to_get_servant_on_the_path_before_using_it():
    readme = (REPO / "README.md").read_text()
    first_use = readme.index("run `servant`")
    assert -1 < readme.find("make install") < first_use
    assert -1 < readme.find("source .venv/bin/activate") < first_use


@pytest.mark.devices
def test_make_setup_says_what_it_installs_and_keeps_pips_chatter_in_a_log(tmp_path):
    """Issue 39 item 14: `make demo` was a minute of silent `pip -q`, then setuptools'
    'BuildBackendWarning: Editable installation … be careful with folders'. Read from make's own
    plan of the commands (`make -n`), which runs none of them."""
    venv = tmp_path / "venv"
    planned = subprocess.run(
        ["make", "-C", str(REPO), "-n", "-B", f"{venv}/.installed", f"VENV={venv}"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert planned.returncode == 0, planned.stderr
    installs = [line for line in planned.stdout.splitlines() if "pip install" in line]
    assert installs and all(
        f"> {venv}/install.log" in line or f">> {venv}/install.log" in line for line in installs
    ), installs
    assert all("cat" in line and "exit 1" in line for line in installs)  # shown on failure
    said = [line for line in planned.stdout.splitlines() if line.startswith("echo")]
    assert any("installing Python packages" in line for line in said), said
