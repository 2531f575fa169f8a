"""What labelling a picture costs: the engine's `folded_in` (featurize, copy, `fold_in`) of one
picture after another into a two-place `fisher-bovw` model taught six pictures a place, in CPU
seconds of this process (`time.process_time`: what a busy machine's other work does not add).

Issue 41 item 6 saw 20-125 s a label, slower with each. Printed: the teach fit's CPU time, the
model file's save (the engine saves after each label), then each label's, with the
regularisation the fit chose (`C_`) and, for comparison, the same model refitted with the C
chosen before issue 38 (0.003, flat probabilities).

    OMP_NUM_THREADS=1 python bench/label_cost.py [--labels 10] [--seed 0]
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import tempfile  # noqa: E402

from bench.common import shared_data  # noqa: E402
from servant_core.engine.learning import Kept, folded_in, save_models  # noqa: E402
from servant_core.library import read_picture  # noqa: E402
from servant_core.recognisers import make_recogniser  # noqa: E402

SCENES = ("cafe", "street", "office")  # two taught, the third labelled as a new place


def cpu(action):
    start = time.process_time()
    result = action()
    return result, time.process_time() - start


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--labels", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    root = shared_data() / "images" / "dev"
    if not root.is_dir():
        print(f"no real pictures at {root}; nothing to measure")
        return 0
    rng = np.random.default_rng(args.seed)
    paths = {s: sorted((root / s).glob("*.jpg")) for s in SCENES}
    chosen = {s: [paths[s][i] for i in rng.permutation(len(paths[s]))] for s in SCENES}
    taught = [read_picture(p) for s in SCENES[:2] for p in chosen[s][:6]]
    labels = [s for s in SCENES[:2] for _ in range(6)]
    model = make_recogniser("image", "fisher-bovw")
    _, fit_s = cpu(lambda: model.fit(model.featurize(taught), labels))
    flat = copy.deepcopy(model)
    flat.C_ = 0.003
    flat._fit_head()
    print(f"teach fit, 12 pictures: {fit_s:.1f} CPU s; C chosen {model.C_:g}")
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "model.npz"
        start = time.perf_counter()
        _, save_s = cpu(lambda: save_models(path, {"visual": model}, print))
        wall = time.perf_counter() - start
        print(f"saving the model after a label: {save_s:.2f} CPU s, {wall:.2f} s on the clock")
    for name, current in (("as fitted", model), ("C 0.003", flat)):
        times = []
        for i in range(args.labels):
            scene = SCENES[i % 3]
            picture = read_picture(chosen[scene][6 + i])
            kept = Kept("image", picture)
            current, seconds = cpu(lambda c=current, k=kept, s=scene: folded_in(c, k, s))
            times.append(seconds)
        print(
            f"labels one after another ({name}): "
            + ", ".join(f"{t:.2f}" for t in times)
            + f" CPU s (median {np.median(times):.2f})"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
