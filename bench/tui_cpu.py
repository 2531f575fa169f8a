"""CPU and peak memory of `servant demo` in a real terminal (tmux), over 30 s.

Targets: at most 30 % of one core with the spectrum at ~30 frames a second, at most 250 MB peak.
Run from the repository root: `python bench/tui_cpu.py [--seconds 30]`.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TICKS = os.sysconf("SC_CLK_TCK")


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime + stime


def peak_rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--warmup", type=float, default=8.0, help="training the demo recognisers")
    args = parser.parse_args()
    if shutil.which("tmux") is None:
        print("tui_cpu: tmux is not installed; install it (scripts/install-system-packages)")
        return 1
    servant = shutil.which("servant") or f"{sys.executable} -m servant_tui"
    session = f"servant-bench-{uuid.uuid4().hex[:8]}"
    with tempfile.TemporaryDirectory() as scratch:
        env = {**os.environ, "SERVANT_DATA_DIR": scratch, "SERVANT_CONFIG_DIR": scratch}
        command = f"cd {ROOT} && exec {servant} demo"
        subprocess.run(
            ["tmux", "new-session", "-d", "-s", session, "-x", "160", "-y", "48", command],
            check=True,
            env=env,
        )
        try:
            pid = int(
                subprocess.run(
                    ["tmux", "display-message", "-p", "-t", session, "#{pane_pid}"],
                    capture_output=True,
                    text=True,
                    check=True,
                ).stdout
            )
            time.sleep(args.warmup)
            start_cpu, start = cpu_seconds(pid), time.monotonic()
            time.sleep(args.seconds)
            used, elapsed = cpu_seconds(pid) - start_cpu, time.monotonic() - start
            peak = peak_rss_mb(pid)
        finally:
            subprocess.run(["tmux", "send-keys", "-t", session, "q"], capture_output=True)
            time.sleep(2)
            subprocess.run(["tmux", "kill-session", "-t", session], capture_output=True)
    share = 100 * used / elapsed
    print(f"servant demo in tmux 160x48 over {elapsed:.0f} s (after {args.warmup:g} s warm-up)")
    print(f"  CPU:         {share:5.1f} % of one core   (target <= 30 %)")
    print(f"  peak memory: {peak:5.0f} MB             (target <= 250 MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
