"""CPU and peak memory of `servant demo` in a real terminal (tmux), over 30 s.

Targets: at most 30 % of one core with the spectrum at ~30 frames a second, at most 250 MB peak.
Run from the repository root: `python bench/tui_cpu.py [--seconds 30]`.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from common import in_tmux, rss_mb, tmux_pid

TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime + stime


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--warmup", type=float, default=8.0, help="training the demo recognisers")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        env = {**os.environ, "SERVANT_DATA_DIR": scratch, "SERVANT_CONFIG_DIR": scratch}
        with in_tmux("demo", env) as session:
            pid = tmux_pid(session)
            time.sleep(args.warmup)
            start_cpu, start = cpu_seconds(pid), time.monotonic()
            time.sleep(args.seconds)
            used, elapsed = cpu_seconds(pid) - start_cpu, time.monotonic() - start
            peak = rss_mb(pid, "VmHWM")
            # of what it holds at the end: its own (anonymous) memory, and pages mapped from
            # files (libraries, BirdNET's weights), which the kernel can drop and processes share
            anonymous, mapped = rss_mb(pid, "RssAnon"), rss_mb(pid, "RssFile")
    share = 100 * used / elapsed
    print(f"servant demo in tmux 160x48 over {elapsed:.0f} s (after {args.warmup:g} s warm-up)")
    print(f"  CPU:         {share:5.1f} % of one core   (target <= 30 %)")
    print(f"  peak memory: {peak:5.0f} MB             (target <= 250 MB)")
    print(f"  at the end:  {anonymous:5.0f} MB its own, {mapped:.0f} MB mapped from files")
    return 0


if __name__ == "__main__":
    sys.exit(main())
