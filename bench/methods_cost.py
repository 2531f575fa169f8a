"""Costs of the methods beyond the paper on one core: a 5 s window through the `codebook` and
`kmeans-encoder` acoustic methods, and a 640×480 frame through the `bovw` visual method
(feature + predict + probabilities; medians of repeated runs, as wall time and as the CPU time
of the thread, which other work on a shared machine does not inflate). The models are trained on the
real data in ../shared/data (or $SERVANT_SHARED_DATA): a few recordings, and 30 pictures per
scene.

Targets: codebook <= 30 ms per window, kmeans-encoder <= 10 ms per window, <= 30 ms per frame.
Run: OMP_NUM_THREADS=1 .venv/bin/python bench/methods_cost.py
"""

from __future__ import annotations

import os

# One core, as on the wearable; set before numpy loads its BLAS.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from common import median_ms, shared_data  # noqa: E402

from servant_core.library import SceneLibrary, featurize_recordings, read_pictures  # noqa: E402
from servant_core.recognisers import make_audio_recogniser  # noqa: E402
from servant_core.recognisers.bovw import BovwVisualRecogniser  # noqa: E402


def acoustic_cost(method: str) -> tuple[float, float]:
    library = SceneLibrary.scan(shared_data() / "audio" / "dev")
    recordings = [r for r in library.recordings if r.scene in ("cafe", "street")]
    model = make_audio_recogniser(method)
    wf = featurize_recordings(recordings, model.featurize, model.rate, model.window_seconds)
    model.fit(wf.features, wf.scenes)
    window = np.random.default_rng(0).normal(0, 0.1, (1, int(model.rate * model.window_seconds)))
    window = window.astype(np.float32)

    def run() -> None:
        X = model.featurize(window)
        model.predict(X)
        model.predict_proba(X)

    return median_ms(run), median_ms(run, clock=time.thread_time)


def visual_cost() -> float:
    library = SceneLibrary.scan(shared_data() / "images" / "dev")
    chosen = [p for s in library.scenes for p in [q for q in library.pictures if q.scene == s][:30]]
    images, kept = read_pictures(chosen)
    model = BovwVisualRecogniser().fit(
        BovwVisualRecogniser().featurize(images), [p.scene for p in kept]
    )
    frame = cv2.resize(images[0], (640, 480), interpolation=cv2.INTER_LINEAR)

    def run() -> None:
        X = model.featurize([frame])
        model.predict(X)
        model.predict_proba(X)

    return median_ms(run)


def main() -> None:
    for method, target in (("codebook", 30), ("kmeans-encoder", 10)):
        ms, cpu_ms = acoustic_cost(method)
        print(
            f"{method}: 5 s window, feature + predict + proba: {ms:6.1f} ms wall,"
            f" {cpu_ms:6.1f} ms CPU (target <= {target})"
        )
    image_ms = visual_cost()
    print(f"bovw: 640x480 frame, feature + predict + proba:  {image_ms:6.1f} ms (target <= 30)")


if __name__ == "__main__":
    main()
