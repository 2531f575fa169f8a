"""How far the time-left estimates of the long jobs are from the time that was really left.

The bars (the CLI's `servant_core.progress`, the app's `WorkProgress`) estimate the time left at a
steady pace: elapsed / done × (total − done). A job whose steps are not alike (files read, then
one long fit counted as nothing) makes that estimate wrong. For three jobs a user waits on — the
demo's start-up, a retrain of a teach-mode library, and the library screen's evaluation — this
records every `on_progress(done, total)` call, and prints for each the estimate's worst ratio to
the truth (estimate / truth or truth / estimate, whichever is larger) over the calls with at
least a second really left, and how long nothing moved before the job ended. A bar that starts
again (its total changes: a new phase, such as a fit after the files are read) estimates the
end of its phase, and is judged against that.

The library is what teach mode leaves: two places of `../shared/data` (cafe, street), three 5 s
recordings and six pictures each.

    OMP_NUM_THREADS=1 python bench/progress_estimates.py
"""

from __future__ import annotations

import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import shared_data  # noqa: E402
from servant_core.audio import read_audio, write_wav  # noqa: E402
from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.engine import Engine, build_demo_engine  # noqa: E402
from servant_core.evaluate import TAUGHT, evaluate_audio  # noqa: E402
from servant_core.library import SceneLibrary  # noqa: E402
from servant_core.recognisers import FRESH_METHODS  # noqa: E402

RECORDINGS = {"cafe": "cafe/audio-ambient-cafe.mp3", "street": "street/audio-ambient-city.mp3"}
RATE = 44100


def teach_library(data: Path, root: Path) -> SceneLibrary:
    for scene, recording in RECORDINGS.items():
        audio = read_audio(data / "audio" / "dev" / recording, RATE)
        for k in range(3):
            write_wav(root / scene / f"rec{k}.wav", audio[k * 5 * RATE : (k + 1) * 5 * RATE], RATE)
        for k, picture in enumerate(sorted((data / "images" / "dev" / scene).glob("*.jpg"))[:6]):
            cv2.imwrite(str(root / scene / f"pic{k}.png"), cv2.imread(str(picture)))
    return SceneLibrary.scan(root)


def timed(
    job: Callable[[Callable[[int, int], None]], Any],
) -> tuple[list[tuple[float, int, int]], float]:
    """Run `job(on_progress)`; the (time, done, total) of each call, and the end, from its start."""
    calls: list[tuple[float, int, int]] = []
    start = time.monotonic()
    job(lambda done, total: calls.append((time.monotonic() - start, done, total)))
    return calls, time.monotonic() - start


def phases(calls: list[tuple[float, int, int]], end: float) -> list[list[tuple[float, int, int]]]:
    """The calls cut where a bar starts again (its total changes or its count goes back), each
    phase led by the time it began: the job's start, or the end of the phase before, or its
    `(0, total)` call (a bar's estimate starts there: `servant_core.progress.Progress`)."""
    cut: list[list[tuple[float, int, int]]] = []
    began = 0.0
    for call in calls:
        if not cut or call[2] != cut[-1][-1][2] or call[1] < cut[-1][-1][1]:
            if cut:
                began = cut[-1][-1][0]
            cut.append([(began, 0, call[2])])
        if call[1] == 0:  # "begins now": the bars start their estimate here
            cut[-1][0] = call
        cut[-1].append(call)
    return cut


def judged(calls: list[tuple[float, int, int]], end: float) -> dict[str, float]:
    """The estimate's worst ratio to the truth, each phase's estimate against its own end (what
    a bar that starts again estimates), and how long nothing moved before the job ended."""
    worst = 1.0
    for phase in phases(calls, end):
        began = phase[0][0]
        finished = next((t for t, done, total in phase[1:] if done >= total), end)
        for t, done, total in phase[1:]:
            truth = finished - t
            if 0 < done < total and truth >= 1.0:
                estimate = (t - began) / done * (total - done)
                worst = max(worst, estimate / truth, truth / max(estimate, 1e-9))
    last = calls[-1][0] if calls else 0.0
    return {
        "worst ratio": worst,
        "still at the end (s)": end - last,
        "phases": len(phases(calls, end)),
    }


def main() -> int:
    data = shared_data()
    if not (data / "audio" / "dev").is_dir():
        print(f"no real data at {data}; nothing to measure")
        return 0
    jobs: dict[str, Callable[[Callable[[int, int], None]], Any]] = {
        "demo start-up": lambda on: build_demo_engine(seed=0, realtime=False, on_progress=on),
    }
    with tempfile.TemporaryDirectory() as folder, library_noise_silenced():
        library = teach_library(data, Path(folder) / "library")
        jobs["retrain (teach library)"] = lambda on: Engine().retrain(library, on_progress=on)
        jobs["evaluate (library screen)"] = lambda on: evaluate_audio(
            library, method=FRESH_METHODS["audio"], protocol=TAUGHT, on_progress=on, on_fold=on
        )  # as the library screen passes them: one bar, listening then the folds
        for name, job in jobs.items():
            calls, end = timed(job)
            figures = judged(calls, end)
            print(
                f"{name:<28} {end:6.1f} s, {len(calls):3d} calls in {figures['phases']} "
                f"phase(s); estimate off by up to {figures['worst ratio']:.1f}x; nothing moved "
                f"in the last {figures['still at the end (s)']:.1f} s",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
