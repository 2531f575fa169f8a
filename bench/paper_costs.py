"""Costs of the paper's pipeline: acoustic feature + predict for one 5 s clip, dominant colours
for one 640x480 frame (medians of repeated runs), and the peak memory of training the paper's
acoustic recogniser on all of ../shared/data/audio/dev (in a fresh process, float32 vectors).

Targets: feature + predict <= 20 ms, dominant colours <= 10 ms, training peak <= 1 GB.
Run: .venv/bin/python bench/paper_costs.py
"""

from __future__ import annotations

import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from common import median_ms, shared_data  # noqa: E402

from servant_core.features.palette import dominant_colours  # noqa: E402
from servant_core.library import SceneLibrary, read_picture  # noqa: E402
from servant_core.recognisers.paper import PaperAcousticRecogniser  # noqa: E402


def acoustic_cost() -> float:
    rng = np.random.default_rng(0)
    model = PaperAcousticRecogniser()
    n = int(model.rate * model.window_seconds)
    train = rng.normal(0, 0.1, (6, n)).astype(np.float32) * np.array(
        [[1], [1], [1], [3], [3], [3]], np.float32
    )
    model.fit(model.featurize(train), ["a"] * 3 + ["b"] * 3)
    clip = rng.normal(0, 0.1, (1, n)).astype(np.float32)

    def run() -> None:
        X = model.featurize(clip)
        model.predict(X)
        model.confidence(X)

    return median_ms(run)


def colour_cost() -> float:
    pictures = sorted((shared_data() / "images" / "dev" / "cafe").glob("*.jpg"))
    if pictures:
        import cv2

        frame = cv2.resize(read_picture(pictures[0]), (640, 480), interpolation=cv2.INTER_CUBIC)
    else:
        frame = np.random.default_rng(0).integers(0, 255, (480, 640, 3), dtype=np.uint8)
    return median_ms(lambda: dominant_colours(frame))


def train_peak_child() -> None:
    from servant_core.library import featurize_recordings

    library = SceneLibrary.scan(shared_data() / "audio" / "dev")
    model = PaperAcousticRecogniser()
    wf = featurize_recordings(library.recordings, model.featurize, model.rate, model.window_seconds)
    start = time.perf_counter()
    model.fit(wf.features, wf.scenes)
    fit_s = time.perf_counter() - start
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"{peak_mb:.0f} {len(wf.scenes)} {wf.features.nbytes / 2**20:.0f} {fit_s:.1f}")


def main() -> None:
    if sys.argv[1:] == ["--train-child"]:
        train_peak_child()
        return
    print(
        "paper acoustic feature + predict, 5 s at 44.1 kHz: "
        f"median {acoustic_cost():.1f} ms (target <= 20)"
    )
    print(f"dominant colours, 640x480 frame: median {colour_cost():.2f} ms (target <= 10)")
    if not (shared_data() / "audio" / "dev").is_dir():
        print("training peak memory: skipped, ../shared/data is not here")
        return
    out = subprocess.run(
        [sys.executable, __file__, "--train-child"], capture_output=True, text=True, check=True
    )
    peak, windows, features, fit_s = out.stdout.split()
    print(
        f"training on all of audio/dev: {windows} windows, feature matrix {features} MB, "
        f"K-Means fit {fit_s} s, peak memory {peak} MB (target <= 1024)"
    )


if __name__ == "__main__":
    main()
