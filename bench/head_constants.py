"""`birdnet`'s head constants chosen on one half of the sources, read on the other (issue 37).

Per window, on the wearer's walk's draws (the same places, recordings and stays as
`bench/wearer_day.py --half H`, through `bench/teach_augment.py`'s cached embeddings and
`measure_draw`, its `none` recipe: the six taught windows alone), for each pair of the head's
background weight (`elsewhere_weight`, the background class's share against the taught places)
and nearest-taught-window cosine (`accept_cosine`): right at the taught places' later windows,
wrong at untaught places, right at other recordings of a taught kind; mean (range) over draws.

    OMP_NUM_THREADS=1 python bench/head_constants.py --half 0|1 [--heads 1:0.5,8:0.4,...]
        [--sizes 2,3,5] [--draws 6] [--cache DIR]
"""

from __future__ import annotations

import argparse
import functools
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import teach_augment  # noqa: E402
from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.recognisers.birdnet import BirdnetAcousticRecogniser  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    teach_augment.add_walk_options(parser)
    parser.add_argument("--half", type=int, choices=(0, 1), required=True)
    parser.add_argument("--heads", default="1:0.5,2:0.5,4:0.5,8:0.5,4:0.45,8:0.4")
    args = parser.parse_args()
    if not (args.data / "audio" / "dev").is_dir():
        print(f"no real data at {args.data}; nothing to measure")
        return 0
    heads = [tuple(float(x) for x in h.split(":")) for h in args.heads.split(",")]
    model = BirdnetAcousticRecogniser()
    with library_noise_silenced():
        recordings = teach_augment.embedded(args.data, model, args.cache)
    augment = teach_augment.Augmenter(model, recordings, args.cache)
    data = teach_augment.walk_data(args.data, recordings, args.half)
    for size in [int(s) for s in args.sizes.split(",")]:
        rates: dict[tuple[float, ...], dict[str, list[float]]] = defaultdict(
            lambda: defaultdict(list)
        )
        for draw in range(args.draws):
            plan = teach_augment.plan(data, size, draw)
            for weight, cosine in heads:
                teach_augment.BirdnetAcousticRecogniser = functools.partial(  # type: ignore[misc]
                    BirdnetAcousticRecogniser, elsewhere_weight=weight, accept_cosine=cosine
                )
                with library_noise_silenced():
                    counts = teach_augment.measure_draw(plan, recordings, augment, ["none"])
                for kind, (hits, n) in counts["none"].items():
                    if n:
                        rates[(weight, cosine)][kind].append(hits / n)
        print(f"half {args.half}, {size} places, {args.draws} draws: mean (range over draws)")
        for head in heads:
            print(
                f"  elsewhere_weight {head[0]:g}, accept_cosine {head[1]:g}: "
                + "  ".join(
                    f"{kind} {teach_augment.spread(rates[head][kind])}"
                    for kind in teach_augment.KINDS
                ),
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
