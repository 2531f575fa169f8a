"""How `kmeans-encoder`'s defaults were chosen: a small grid, scored by cross-validation grouped
by recording inside one training library (never on a test split).

Two criteria, both inside the library given:
- grouped: GroupKFold over recordings (5 folds): whole recordings held out, the rest train
  (a place heard through another microphone);
- teach: the first 3 windows of every recording train, the last 40 % of each tests (the
  `fewshot` protocol's k = 3, inside the library).
The chosen point has the best mean of the two; ties go to the cheaper model.

    OMP_NUM_THREADS=1 python bench/kmeans_encoder_search.py [--data ../shared/data/audio/dev]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np
from sklearn.model_selection import GroupKFold

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import shared_data  # noqa: E402

from servant_core.evaluate import AudioPlan, audio_plans, evaluate_windows  # noqa: E402
from servant_core.library import SceneLibrary, featurize_recordings  # noqa: E402
from servant_core.recognisers.kmeans_encoder import KMeansEncoderAcousticRecogniser  # noqa: E402

# The last of several rounds (earlier ones settled crops=4, eq_strength=0.45, 40 bands,
# three codebooks of 64: see the README's section on issue 11).
GRID = {
    "C": [0.05, 0.5],
    "augment": [2, 8],
}
FOLDS = 5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data() / "audio" / "dev")
    args = parser.parse_args()
    library = SceneLibrary.scan(args.data)
    probe = KMeansEncoderAcousticRecogniser()
    wf = featurize_recordings(library.recordings, probe.featurize, probe.rate, 5.0)
    names = [str(r.path.relative_to(library.root)) for r in wf.recordings]
    folds = GroupKFold(FOLDS).split(wf.features, wf.scenes, wf.recording)
    trains = [np.isin(np.arange(len(wf.scenes)), train) for train, _ in folds]
    grouped = AudioPlan("grouped", trains, [~t for t in trains])
    teach = audio_plans(wf, "fewshot", (3,))[0]
    results = []
    print(f"{'params':<40} {'grouped':>8} {'teach':>8} {'mean':>8} {'s':>5}")
    for values in itertools.product(*GRID.values()):
        params = dict(zip(GRID, values, strict=True))
        start = time.perf_counter()
        rows = evaluate_windows(
            wf,
            names,
            [grouped, teach],
            lambda seed, params=params: KMeansEncoderAcousticRecogniser(**params),
        )
        g, t = (r["balanced_accuracy"] for r in rows)
        results.append(((g + t) / 2, params))
        print(
            f"{str(params):<40} {g:>8.3f} {t:>8.3f} {(g + t) / 2:>8.3f}"
            f" {time.perf_counter() - start:>5.0f}",
            flush=True,
        )
    best = max(results, key=lambda r: r[0])
    print(f"chosen: {best[1]} (mean {best[0]:.3f})")


if __name__ == "__main__":
    main()
