"""What the benchmark scripts share: where the real data is, and a median timer."""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def shared_data() -> Path:
    """$SERVANT_SHARED_DATA, else `../shared/data` beside the repository (it may not exist)."""
    return Path(os.environ.get("SERVANT_SHARED_DATA", REPO.parent / "shared" / "data"))


def median_ms(
    fn: Callable[[], object], repeats: int = 30, clock: Callable[[], float] = time.perf_counter
) -> float:
    """Median time of `fn` in milliseconds by `clock` (wall time; `time.thread_time` counts the
    CPU this thread used, which other work on a shared machine does not inflate), after one
    warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        start = clock()
        fn()
        times.append((clock() - start) * 1000)
    return statistics.median(times)


def rss_mb(pid: int, field: str = "VmRSS") -> float:
    """A process's resident memory now (`VmRSS`) or at its peak (`VmHWM`), in MB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    return float("nan")


@contextlib.contextmanager
def in_tmux(
    arguments: str, env: dict[str, str], size: tuple[int, int] = (160, 48)
) -> Iterator[str]:
    """Run `servant ARGUMENTS` in a real terminal (a detached tmux session, cwd the repository);
    yields the session's name; quits the application (`q`) and ends the session afterwards."""
    if shutil.which("tmux") is None:
        raise SystemExit("tmux is not installed; install it (scripts/install-system-packages)")
    servant = shutil.which("servant") or f"{sys.executable} -m servant_tui"
    session = f"servant-bench-{uuid.uuid4().hex[:8]}"
    command = f"cd {REPO} && exec {servant} {arguments}"
    width, height = size
    subprocess.run(
        ["tmux", "new-session", "-d", "-s", session, "-x", str(width), "-y", str(height), command],
        check=True,
        env=env,
    )
    try:
        yield session
    finally:
        subprocess.run(["tmux", "send-keys", "-t", session, "q"], capture_output=True)
        time.sleep(2)
        subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)


def tmux_pid(session: str) -> int:
    """The process id of the program running in the tmux session."""
    answer = subprocess.run(
        ["tmux", "display-message", "-p", "-t", session, "#{pane_pid}"],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(answer.stdout)


def add_arrive_sure(parser: argparse.ArgumentParser, several: bool = False) -> None:
    """`--arrive-alone P`: the probability at which one sound window alone names a place arriving
    (the decision pipeline's `arrive_sure`, default Servant's); `none`: two windows in a row.
    `several`: a list of them, each walked in turn (a list, also by default)."""
    from servant_core.fusion.pipeline import ARRIVE_SURE

    def probability(text: str) -> float | None:
        if text.lower() == "none":
            return None
        value = float(text)
        if not 0.5 <= value <= 1.0:
            raise argparse.ArgumentTypeError("give a probability from 0.5 to 1, or none")
        return value

    parser.add_argument(
        "--arrive-alone",
        type=probability,
        nargs="+" if several else None,
        default=[ARRIVE_SURE] if several else ARRIVE_SURE,
        metavar="P",
        help="one sound window alone names a place arriving when it gives it P or more "
        "(0.5 to 1; none: two windows in a row only; default: Servant's, %(default)s)",
    )
