"""Memory of `servant demo` over a long run, in a real terminal (tmux) or headless.

Samples resident memory every `--every` seconds for `--minutes`; in the terminal it can retrain
the recognisers from the library screen (`l`, then `R`) at `--retrain-at` minutes. Prints the
samples, the growth per hour after `--warmup` minutes (least-squares slope) and the peak.
Targets (issue 13): at most 5 MB/h after the first 10 minutes, at most 250 MB after a retrain.

Run from the repository root: `python bench/soak.py --minutes 60 --mode tui --retrain-at 15`
(a retrain's step is left out of the growth: it is measured before the retrain and from a
minute after it). What grows, and why: run the
TUI with `SERVANT_MEMTRACE=FILE` (see `servant_tui/memtrace.py`).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator

import numpy as np
from common import REPO, in_tmux, rss_mb, tmux_pid


@contextlib.contextmanager
def headless(env: dict[str, str]) -> Iterator[int]:
    process = subprocess.Popen(
        [sys.executable, "-m", "servant_tui", "demo", "--headless"],
        cwd=REPO,
        env=env,
        stdout=subprocess.DEVNULL,
    )
    try:
        yield process.pid
    finally:
        process.terminate()
        process.wait(timeout=30)


def press(session: str, *keys: str) -> None:
    for key in keys:
        subprocess.run(["tmux", "send-keys", "-t", session, key], check=True)
        time.sleep(1.0)


def screen_text(session: str) -> str:
    answer = subprocess.run(
        ["tmux", "capture-pane", "-p", "-t", session], capture_output=True, text=True, check=True
    )
    return answer.stdout


def start_retrain(session: str) -> None:
    """The library screen (`l`), then retrain (`R`). The demo asks about unknown places with a
    prompt that would take those keys as a label: `escape` skips it first (no new one comes for
    five minutes, and none while the library is in front)."""
    press(session, "Escape", "l", "R")


def print_growth(samples: list[tuple[float, float]], start: float, end: float, when: str) -> None:
    """The least-squares growth per hour of the samples taken from `start` to `end` minutes."""
    part = np.array([(t, mb) for t, mb in samples if start <= t < end])
    if len(part) < 2:
        print(f"  growth {when}: too few samples to measure")
        return
    slope = np.polyfit(part[:, 0] / 60, part[:, 1], 1)[0]
    span = f"{part[0, 0]:.0f}-{part[-1, 0]:.0f} min"
    print(f"  growth {when} ({span}): {slope:+.1f} MB/h   (target <= 5 MB/h)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--every", type=float, default=30.0, help="seconds between samples")
    parser.add_argument("--warmup", type=float, default=10.0, help="minutes left out of the slope")
    parser.add_argument("--mode", choices=("tui", "headless"), default="tui")
    parser.add_argument("--retrain-at", type=float, help="minutes; tui mode only")
    args = parser.parse_args()
    samples: list[tuple[float, float]] = []
    retrained_at: float | None = None
    retrain_done_at: float | None = None
    with tempfile.TemporaryDirectory() as scratch:
        # A tmux server of our own (its socket in `scratch`): one shared with other programs
        # may be killed under a long run, and would not hand the new session our environment.
        os.environ["TMUX_TMPDIR"] = scratch
        env = {**os.environ, "SERVANT_DATA_DIR": scratch, "SERVANT_CONFIG_DIR": scratch}
        runner = in_tmux("demo", env) if args.mode == "tui" else headless(env)
        with runner as handle:
            pid = tmux_pid(handle) if isinstance(handle, str) else handle
            start = time.monotonic()
            while (elapsed := (time.monotonic() - start) / 60) < args.minutes:
                samples.append((elapsed, rss_mb(pid)))
                print(f"{elapsed:6.1f} min  {samples[-1][1]:6.1f} MB", flush=True)
                if (
                    isinstance(handle, str)
                    and args.retrain_at is not None
                    and retrained_at is None
                    and elapsed >= args.retrain_at
                ):
                    start_retrain(handle)
                    retrained_at = elapsed
                    print(f"{elapsed:6.1f} min  retrain started (library screen, R)", flush=True)
                if (
                    isinstance(handle, str)
                    and retrained_at is not None
                    and retrain_done_at is None
                    and "retrained on" in screen_text(handle)
                ):
                    retrain_done_at = elapsed
                    print(f"{elapsed:6.1f} min  retrain done (the library says so)", flush=True)
                time.sleep(args.every)
            peak = rss_mb(pid, "VmHWM")
    print(f"servant demo ({args.mode}), {args.minutes:g} min, a sample every {args.every:g} s")
    # A retrain's own step is not growth: the slope is taken before it and again after it.
    before = retrained_at if retrained_at is not None else math.inf
    print_growth(samples, args.warmup, before, f"after {args.warmup:g} min")
    if retrain_done_at is not None:
        print_growth(samples, retrain_done_at + 1, math.inf, "after the retrain")
    if retrained_at is not None:
        if retrain_done_at is None:
            print("  the retrain never said it was done: no figure after a retrain")
        else:
            after = [mb for t, mb in samples if t >= retrain_done_at]
            print(
                f"  after the retrain: most {max(after):.0f} MB, last {after[-1]:.0f} MB"
                "   (target <= 250 MB)"
            )
    print(f"  peak: {peak:.0f} MB; last: {samples[-1][1]:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
