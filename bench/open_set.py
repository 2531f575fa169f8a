"""Open set on the real recordings: with one scene left out of training, how many of its
windows are reported unknown, and how many known-scene windows are still recognised.

For each held-out scene: train on the first 60 % of every other recording's windows
(temporal split), test on the rest of them (known) and on every window of the held-out scene.

"ceiling@5%" asks how separable the two are at all, whatever the calibration: the share of
held-out windows whose novelty exceeds the threshold that rejects exactly 5 % of the known test
windows (chosen on the test windows themselves, so it is a ceiling, not a result).

    python bench/open_set.py [--method codebook] [--param reject_margin=1.5 ...]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.evaluate import temporal_split  # noqa: E402
from servant_core.library import SceneLibrary, featurize_recordings  # noqa: E402
from servant_core.recognisers import UNKNOWN, make_recogniser  # noqa: E402


def data_root() -> Path:
    env = os.environ.get("SERVANT_SHARED_DATA")
    root = Path(env) if env else Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
    return root / "audio" / "dev"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="codebook")
    parser.add_argument("--param", action="append", default=[], help="name=value (JSON value)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    params = {k: json.loads(v) for k, v in (p.split("=", 1) for p in args.param)}
    library = SceneLibrary.scan(data_root())
    probe = make_recogniser("audio", args.method, **params)
    wf = featurize_recordings(library.recordings, probe.featurize, probe.rate, probe.window_seconds)
    train = temporal_split(wf.recording, wf.position)
    rows = []
    for held_out in library.scenes:
        known = wf.scenes != held_out
        model = make_recogniser("audio", args.method, **params)
        model.fit(wf.features[known & train], wf.scenes[known & train])
        unknown_pred = model.predict(wf.features[~known])
        known_test = known & ~train
        known_pred = model.predict(wf.features[known_test])
        known_novelty = model.novelty(wf.features[known_test])
        ceiling = np.mean(model.novelty(wf.features[~known]) > np.quantile(known_novelty, 0.95))
        rows.append(
            {
                "held_out": held_out,
                "held_out_unknown": float(np.mean(unknown_pred == UNKNOWN)),
                "known_recognised": float(np.mean(known_pred == wf.scenes[known_test])),
                "known_rejected": float(np.mean(known_pred == UNKNOWN)),
                "ceiling_at_5pct": float(ceiling),
                "n_held_out": int((~known).sum()),
                "n_known_test": int(known_test.sum()),
            }
        )
    summary = {
        "method": args.method,
        "params": params,
        "mean_held_out_unknown": float(np.mean([r["held_out_unknown"] for r in rows])),
        "mean_known_recognised": float(np.mean([r["known_recognised"] for r in rows])),
        "mean_ceiling_at_5pct": float(np.mean([r["ceiling_at_5pct"] for r in rows])),
        "folds": rows,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
        return
    print(f"{'held out':<14}{'unknown':>9}{'known ok':>10}{'known rej':>11}{'ceiling@5%':>12}")
    for r in rows:
        print(
            f"{r['held_out']:<14}{r['held_out_unknown']:>9.3f}"
            f"{r['known_recognised']:>10.3f}{r['known_rejected']:>11.3f}"
            f"{r['ceiling_at_5pct']:>12.3f}"
        )
    print(
        f"{'mean':<14}{summary['mean_held_out_unknown']:>9.3f}"
        f"{summary['mean_known_recognised']:>10.3f}{'':>11}"
        f"{summary['mean_ceiling_at_5pct']:>12.3f}"
    )


if __name__ == "__main__":
    with library_noise_silenced():  # mpg123 warns of one real MP3 on descriptor 2
        main()
