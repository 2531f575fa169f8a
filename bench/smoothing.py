"""Do live decisions hold still in one place and follow a real change? Before and after smoothing.

Real recordings replayed back to back. The acoustic method is trained on the first 60 % of each
recording's windows (`temporal_split`); test streams are the last 40 % of one recording per
scene, of several scenes, concatenated in a random order (a walk from place to place). Each
window is decided by the argmax of its probabilities (raw), or of the forward filter's
(`servant_core.fusion.smoothing.SceneSmoother`, smoothed).

- wrong flips per minute: the decision changes to a scene that is not where the stream is;
- seconds to the right scene after a change: from the change to the end of the first window
  decided right (5 s = the first window of the new place is already right); a stretch never
  decided right counts as its length and is reported separately.

The stay probability and the evidence floor are chosen on the training part only: a model fitted
on the first 60 % of the training windows predicts the rest of them, streams are built from those
in the same way, and of the settings that leave at most `LATE_TOLERANCE` of the changes more
late (beyond two windows) than the raw decisions do, the one with the fewest wrong flips wins
(ties: the least sticky). The test streams are seen once, at the end.

    python bench/smoothing.py [--method codebook] [--streams 40] [--seed 0]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from common import shared_data  # noqa: E402

from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.evaluate import featurize_library_audio, temporal_split  # noqa: E402
from servant_core.fusion.smoothing import SceneSmoother  # noqa: E402
from servant_core.library import SceneLibrary  # noqa: E402
from servant_core.recognisers import make_audio_recogniser  # noqa: E402

STAYS = (0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 0.8, 0.9, 0.95)
FLOORS = (0.02, 0.05, 0.1, 0.2, 0.4, 0.6, 0.8)
# for comparison: a setting that holds a single sure odd window (tests/test_smoothing.py)
STICKY_STAY, STICKY_FLOOR = 0.95, 0.1
SCENES_PER_STREAM = 5
CHANGE_WINDOWS = 2
LATE_TOLERANCE = 0.05


@dataclass
class Stream:
    truth: list[str]  # the scene of each window
    proba: np.ndarray  # (n, scenes) the method's probabilities for each window
    starts: list[int]  # the index where each recording's stretch begins


def make_streams(
    proba: np.ndarray,
    scenes: np.ndarray,
    recording: np.ndarray,
    n_streams: int,
    rng: np.random.Generator,
) -> list[Stream]:
    """Streams of `SCENES_PER_STREAM` scenes in a random order, one random recording of each,
    its windows in their recorded order (rows of `proba` are in recording, position order)."""
    by_scene: dict[str, list[int]] = {}
    for r in np.unique(recording):
        by_scene.setdefault(str(scenes[recording == r][0]), []).append(int(r))
    names = sorted(by_scene)
    streams = []
    for _ in range(n_streams):
        chosen = rng.choice(names, size=min(SCENES_PER_STREAM, len(names)), replace=False)
        rows, truth, starts = [], [], []
        for scene in chosen:
            r = by_scene[str(scene)][rng.integers(len(by_scene[str(scene)]))]
            index = np.flatnonzero(recording == r)
            starts.append(len(truth))
            rows.extend(index.tolist())
            truth.extend([str(scene)] * len(index))
        streams.append(Stream(truth, proba[rows], starts))
    return streams


def decisions(stream: Stream, columns: list[str], smoother: SceneSmoother | None) -> list[str]:
    out = []
    for row in stream.proba:
        scores = {s: float(p) for s, p in zip(columns, row, strict=True)}
        if smoother is not None:
            scores = smoother.update(scores)
        out.append(max(scores, key=lambda s: scores[s]))
    if smoother is not None:
        smoother.reset()
    return out


@dataclass
class Figures:
    minutes: float
    wrong_flips: int
    delays_s: list[float]  # per change, from the change to the end of the first right window
    never: int  # changes whose stretch was never decided right
    late: int  # changes not shown within CHANGE_WINDOWS windows

    @property
    def flips_per_minute(self) -> float:
        return self.wrong_flips / self.minutes


def measure(
    streams: list[Stream], columns: list[str], smoother: SceneSmoother | None, window_s: float
) -> Figures:
    n_windows = wrong = never = late = 0
    delays: list[float] = []
    for stream in streams:
        said = decisions(stream, columns, smoother)
        n_windows += len(said)
        wrong += sum(
            1 for t in range(1, len(said)) if said[t] != said[t - 1] and said[t] != stream.truth[t]
        )
        # every stretch after the first is a change of place
        ends = [*stream.starts[1:], len(said)]
        for start, end in zip(stream.starts[1:], ends[1:], strict=True):
            right = [t for t in range(start, end) if said[t] == stream.truth[t]]
            if not right:
                never += 1
            first = (right[0] if right else end) - start + 1
            delays.append(first * window_s)
            late += first > CHANGE_WINDOWS
    return Figures(n_windows * window_s / 60.0, wrong, delays, never, late)


def choose_setting(
    streams: list[Stream], columns: list[str], window_s: float
) -> tuple[float, float]:
    """The (stay, floor) with the fewest wrong flips on `streams` among those that leave at most
    `LATE_TOLERANCE` of the changes more late (beyond two windows) than the raw decisions; ties
    keep the least sticky."""
    raw = measure(streams, columns, None, window_s)
    allowed_late = raw.late + LATE_TOLERANCE * len(raw.delays_s)
    best: tuple[int, float, float] | None = None
    for stay in STAYS:
        for floor in FLOORS:
            f = measure(streams, columns, SceneSmoother(stay, floor), window_s)
            if f.late <= allowed_late and (best is None or f.wrong_flips < best[0]):
                best = (f.wrong_flips, stay, floor)
    if best is None:
        # nothing keeps up with the raw decisions: the least sticky setting tried
        return STAYS[0], FLOORS[-1]
    return best[1], best[2]


def line(name: str, f: Figures) -> str:
    n = len(f.delays_s)
    return (
        f"{name:<36} {f.flips_per_minute:>8.2f} {statistics.median(f.delays_s):>10.1f}"
        f" {statistics.mean(f.delays_s):>8.1f} {(n - f.late) / n:>11.2f} {f.never:>6d}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="codebook", help="acoustic method (default codebook)")
    parser.add_argument("--streams", type=int, default=40, help="random test streams")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    library = SceneLibrary.scan(shared_data() / "audio" / "dev")
    probe = make_audio_recogniser(args.method)
    wf = featurize_library_audio(library, probe)
    window_s = probe.window_seconds
    train = temporal_split(wf.recording, wf.position)
    rng = np.random.default_rng(args.seed)

    # Choosing the filter's setting inside the training part: an inner temporal split of it.
    inner = np.zeros(len(train), dtype=bool)
    inner[train] = temporal_split(wf.recording[train], wf.position[train])
    held = train & ~inner
    model = make_audio_recogniser(args.method).fit(wf.features[inner], wf.scenes[inner])
    valid = make_streams(
        model.predict_proba(wf.features[held]),
        wf.scenes[held],
        wf.recording[held],
        args.streams,
        rng,
    )
    stay, floor = choose_setting(valid, list(model.scenes_), window_s)

    model = make_audio_recogniser(args.method).fit(wf.features[train], wf.scenes[train])
    columns = list(model.scenes_)
    test = make_streams(
        model.predict_proba(wf.features[~train]),
        wf.scenes[~train],
        wf.recording[~train],
        args.streams,
        rng,
    )
    raw = measure(test, columns, None, window_s)
    smooth = measure(test, columns, SceneSmoother(stay, floor), window_s)
    minutes = raw.minutes
    print(
        f"{args.method}: {len(test)} test streams of {SCENES_PER_STREAM} scenes, {minutes:.0f} min,"
        f" {len(raw.delays_s)} changes of place; {window_s:g} s windows"
    )
    print(f"chosen on the training part: stay {stay:g}, floor {floor:g}")
    print(
        f"{'decisions':<36} {'wrong/min':>8} {'median s':>10} {'mean s':>8}"
        f" {'within 2 w.':>11} {'never':>6}"
    )
    print(line("raw (argmax per window)", raw))
    print(line(f"smoothed (stay {stay:g}, floor {floor:g})", smooth))
    sticky = SceneSmoother(STICKY_STAY, STICKY_FLOOR)
    print(
        line(
            f"stickier (stay {STICKY_STAY:g}, floor {STICKY_FLOOR:g})",
            measure(test, columns, sticky, window_s),
        )
    )


if __name__ == "__main__":
    with library_noise_silenced():  # mpg123 warns of one real MP3 on descriptor 2
        main()
