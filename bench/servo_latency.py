"""Round-trip latency of a command to the servo emulator over a real pty, through pyserial.

One round trip = the link encodes one rate-limited step for one joint, writes it, then asks
the controller for every joint's position and waits for the reply
(`move_to(pose, wait=False)` + `read_positions()`). Median over 100, per protocol.
Run: `python bench/servo_latency.py`.
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from servant_core.servo.emulator import start_emulator  # noqa: E402
from servant_core.servo.link import ServoLink  # noqa: E402
from servant_core.settings import default_joints  # noqa: E402

ROUNDS = 100


def measure(protocol: str) -> tuple[float, float, float]:
    emulator, port = start_emulator(protocol)
    try:
        with ServoLink.open(port, protocol, default_joints()) as link:
            link.arm()
            timings = []
            for i in range(ROUNDS + 5):
                start = time.perf_counter()
                link.move_to({"shoulder": 10 + i % 2}, wait=False)
                link.read_positions()
                timings.append(time.perf_counter() - start)
            timings = timings[5:]  # the first few warm up the pty and the parser
    finally:
        emulator.stop()
    ms = sorted(t * 1000 for t in timings)
    return statistics.median(ms), ms[int(0.9 * len(ms))], ms[-1]


def main() -> None:
    print(f"servo round trip over a pty (move + position query), {ROUNDS} rounds")
    print(f"{'protocol':<10}{'median ms':>10}{'p90 ms':>10}{'max ms':>10}")
    for protocol in ("maestro", "ssc32", "firmata"):
        median, p90, worst = measure(protocol)
        print(f"{protocol:<10}{median:>10.3f}{p90:>10.3f}{worst:>10.3f}")


if __name__ == "__main__":
    main()
