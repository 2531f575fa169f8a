"""The numerical libraries' pools are one thread in Servant's processes, unless the user's
environment sizes them; start-up work runs on a thread a core, its results in order
(servant_core.threads)."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from servant_core.demo.scenes import SCENES, TRAIN, synth_picture, synth_window, training_set
from servant_core.threads import POOLS, one_thread_pools, results_in_order

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


@pytest.mark.devices
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


def test_results_come_in_the_jobs_order_whichever_ends_first():
    def job(value, delay):
        return lambda: (time.sleep(delay), value)[1]

    jobs = [job("slow", 0.2), job("quick", 0.0), job("middling", 0.05)]
    assert list(results_in_order(jobs)) == ["slow", "quick", "middling"]


def test_a_failing_job_raises_where_its_result_is_due_and_the_rest_are_not_begun():
    begun = []

    def failing():
        raise ValueError("no such scene")

    def later(i):
        def run():
            begun.append(i)
            time.sleep(0.05)
            return i

        return run

    gate = threading.Event()
    jobs = [lambda: gate.wait(5) and "first", failing, *(later(i) for i in range(20))]
    results = results_in_order(jobs)
    gate.set()
    assert next(results) == "first"
    with pytest.raises(ValueError, match="no such scene"):
        next(results)  # and the jobs not yet begun are cancelled, not run
    assert len(begun) < 20


def test_the_demo_training_set_is_the_same_on_threads_as_made_one_by_one():
    windows, window_scenes, pictures, picture_scenes = training_set(3, 2, 2)
    i = 0
    for s, scene in enumerate(SCENES):
        for k in range(2):
            alone = synth_window(scene, np.random.default_rng([3, TRAIN, s, 0, k]))
            assert np.array_equal(windows[i], alone) and window_scenes[i] == scene
            picture = synth_picture(scene, np.random.default_rng([3, TRAIN, s, 1, k]))
            assert np.array_equal(pictures[i], picture) and picture_scenes[i] == scene
            i += 1
