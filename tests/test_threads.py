"""The numerical libraries' pools are one thread in Servant's processes, unless the user's
environment sizes them (servant_core.threads)."""

from __future__ import annotations

import os
import subprocess
import sys

from servant_core.threads import POOLS, one_thread_pools

PROBE = """
import os, sys
from servant_tui.main import main
try:
    main(["--help"])
except SystemExit:
    pass
import numpy, threadpoolctl  # as a command that goes on to compute would
sizes = {i["internal_api"]: i["num_threads"] for i in threadpoolctl.threadpool_info()}
print(os.environ["OMP_NUM_THREADS"], sizes, file=sys.stderr)
"""


def test_one_thread_pools_sets_what_the_environment_leaves_unset(monkeypatch):
    for name in POOLS:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "4")  # the user's choice stays
    one_thread_pools()
    assert os.environ["OMP_NUM_THREADS"] == "1"
    assert os.environ["MKL_NUM_THREADS"] == "1"
    assert os.environ["OPENBLAS_NUM_THREADS"] == "4"


def test_the_servant_command_starts_numpy_with_one_thread_pools():
    env = {k: v for k, v in os.environ.items() if k not in POOLS}
    done = subprocess.run(
        [sys.executable, "-c", PROBE], capture_output=True, text=True, env=env, timeout=120
    )
    assert done.returncode == 0, done.stderr
    omp, sizes = done.stderr.strip().splitlines()[-1].split(" ", 1)
    assert omp == "1"
    assert "'openblas': 1" in sizes, sizes


def test_the_engines_tested_in_this_process_have_one_thread_pools_too():
    """conftest sizes the pools before numpy loads, as the command does (a plugin that loaded
    numpy first would leave them at one thread per core)."""
    import threadpoolctl

    sizes = {i["internal_api"]: i["num_threads"] for i in threadpoolctl.threadpool_info()}
    assert sizes.get("openblas") == 1, sizes
