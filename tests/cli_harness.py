"""Run the `servant` command line the way the fuzz and boundary tests need it.

`run_cli` calls the entry point in-process (fast: thousands of calls a run) and captures what
it prints; `run_cli_subprocess` runs the real console script in a child process, bounded in time
and address space, and reports the child's own peak memory (from `os.wait4`).
"""

from __future__ import annotations

import contextlib
import io
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servant_core.cli import main

REPO = Path(__file__).resolve().parents[1]
ONE_GB = 1024**3


@dataclass
class Outcome:
    code: int
    out: str
    err: str
    seconds: float
    peak_mb: float = 0.0


def run_cli(*argv: str) -> Outcome:
    """`servant ARGV` in this process; an exception other than SystemExit propagates (that is
    a traceback the user would have seen, and fails the test)."""
    out, err = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(argv))
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else 2
    return Outcome(code, out.getvalue(), err.getvalue(), time.perf_counter() - start)


def assert_clear(outcome: Outcome, seconds: float = 30.0) -> None:
    """Success, or exactly one `servant: error: ...` line and exit status 2; never a traceback
    nor a hang."""
    assert "Traceback" not in outcome.err, outcome.err
    assert outcome.seconds < seconds, f"took {outcome.seconds:.1f} s"
    if outcome.code != 0:
        assert outcome.code == 2, (outcome.code, outcome.err)
        lines = [line for line in outcome.err.splitlines() if not line.startswith("servant: warn")]
        assert len(lines) == 1 and lines[0].startswith("servant: error: "), outcome.err


def assert_refused(outcome: Outcome, *words: str) -> None:
    assert outcome.code == 2, (outcome.code, outcome.out, outcome.err)
    assert_clear(outcome)
    for word in words:
        assert word in outcome.err, outcome.err


# The child reports its own peak (VmHWM of its image after exec): the rusage of a forked child
# also counts the pages it shared with the test process before exec, a gigabyte once the suite
# has run the picture tests.
CHILD_MAIN = """
import atexit, os, sys
from pathlib import Path

def report_peak():
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            Path(os.environ["SERVANT_TEST_PEAK_FILE"]).write_text(line.split()[1])

atexit.register(report_peak)
from servant_tui.main import main
sys.exit(main())
"""


def run_cli_subprocess(
    *argv: str, timeout: float = 60.0, address_space: int = 4 * ONE_GB, file_size: int = -1
) -> Outcome:
    """The console script in a child: killed after `timeout`, its address space capped (a
    runaway allocation fails there, not on the machine), `peak_mb` its maximum resident size."""

    def limits() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (address_space, address_space))
        if file_size >= 0:
            resource.setrlimit(resource.RLIMIT_FSIZE, (file_size, file_size))

    peak_file = Path(tempfile.mkdtemp()) / "peak-kb"
    env = {
        **os.environ,
        "OPENBLAS_NUM_THREADS": "1",
        "OMP_NUM_THREADS": "1",
        "SERVANT_TEST_PEAK_FILE": str(peak_file),
    }
    start = time.perf_counter()
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        child = subprocess.Popen(
            [
                sys.executable,
                "-c",
                CHILD_MAIN,
            ]
            + list(argv),
            stdout=out,
            stderr=err,
            preexec_fn=limits,
            cwd=REPO,
            env=env,
        )
        timer = threading.Timer(timeout, lambda: os.kill(child.pid, signal.SIGKILL))
        timer.start()
        try:
            _, status, usage = os.wait4(child.pid, 0)
        finally:
            timer.cancel()
            child.returncode = 0  # reaped by wait4 above; keeps Popen from waiting again
        out.seek(0)
        err.seek(0)
        return Outcome(
            os.waitstatus_to_exitcode(status),
            out.read().decode(errors="replace"),
            err.read().decode(errors="replace"),
            time.perf_counter() - start,
            _own_peak_kb(peak_file, usage.ru_maxrss) / 1024,
        )


def _own_peak_kb(peak_file: Path, fallback_kb: int) -> float:
    """The child's own peak if it lived to report it (killed, it could not: then the rusage
    figure, which can only be larger)."""
    try:
        return float(peak_file.read_text())
    except (OSError, ValueError):
        return float(fallback_kb)
    finally:
        shutil.rmtree(peak_file.parent, ignore_errors=True)


def zip_bomb(path: Path) -> Path:
    """A 0.3 MB `.npz` whose one member inflates to 300 MB: a model file not to read whole."""
    header = np.lib.format.header_data_from_array_1_0(np.zeros(0, np.uint8))
    header["shape"] = (300 * 1024**2,)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        with archive.open("visual/centres.npy", "w") as member:
            np.lib.format.write_array_header_1_0(member, header)
            for _ in range(300):
                member.write(bytes(1 << 20))
    return path
