"""Augmenting what the wearer taught (issue 37): does a taught place then hold on its later windows?

`birdnet` misses its own taught places a third of the time on recordings from other sources
(`bench/wearer_day.py --half 1`: right moves 0.64-0.84) while rarely naming untaught ones. This
bench asks, per window and without the live engine's smoothing, whether copies of the taught
windows made at teach time (gain, equalisation, time shifts, the background mixed in) help:

- the recordings of `audio/dev` (one half of the sources, `wearer_day.source_half`, with the
  `moodist-*` background recordings of both halves), their first 38 windows of 5 s embedded
  once by the recogniser's own `featurize` at its own rate and kept in `--cache`;
- the wearer's walk's draws (`wearer_day.plan_walk`, `default_rng([size, draw])`: the same
  places, recordings and stays as `bench/wearer_day.py --half H`), each taught place's first six
  windows taught; each recipe's copies of them added as extra taught windows of their visit;
- per window, the name `birdnet` gives (`answers`: the head, somewhere else, the nearest taught
  window's acceptance): right at the taught places' later windows, wrong (any taught place) at
  untaught places (other scenes' recordings, `moodist-*` left out), right at other recordings of
  a taught kind.

Each recipe is measured three ways: its copies count for the head, the nearest-taught-window
acceptance and the novelty centroids as windows the wearer taught (`heard`); only for the head
(`derived`, as `kmeans-encoder`'s equalised copies are); or only for the acceptance (`accept`:
the head, its scale and the novelty centroids as without them).

Recipes (copies a taught window, drawn from a seed of the recording's name and the recipe):
- `gain`: 2 copies, a gain of -12..12 dB;
- `eq`: 3 copies, a tilt of -6..6 dB at 125 Hz and 8 kHz about 1 kHz and eight bands of
  +-6 dB (log-spaced 50 Hz-20 kHz, smooth in log frequency);
- `shift`: the five windows between the taught ones (2.5 s, 7.5 s ... 22.5 s into the 30 s);
- `mix`: 3 copies, 5 s of a `moodist-*` recording (the background's own sound) added at a
  signal-to-noise ratio of 5..20 dB;
- `all`: 3 copies, `eq`, `gain` and `mix` together;
- `emb-mix`: 3 copies made from the embeddings alone (what a `fit` that only sees embeddings
  can do): (1-a) x + a b, b a window of the shipped background (`background_birdnet.npz`),
  a drawn from 0.1..0.3;
- `emb-mid`: the mean of each two consecutive taught windows' embeddings (five a place), what
  `shift` becomes where only embeddings are at hand.

    OMP_NUM_THREADS=1 python bench/teach_augment.py --half 0|1 [--sizes 2,3,5] [--draws 6]
        [--recipes none,gain,eq,shift,mix,all,emb-mix,emb-mid] [--modes heard,derived,accept]
        [--cache DIR] [--json FILE]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import wearer_day  # noqa: E402
from bench.common import shared_data  # noqa: E402
from servant_core.audio import read_audio  # noqa: E402
from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.errors import ServantError  # noqa: E402
from servant_core.library import TEACH_WINDOWS  # noqa: E402
from servant_core.recognisers import UNKNOWN  # noqa: E402
from servant_core.recognisers.birdnet import BirdnetAcousticRecogniser  # noqa: E402
from servant_core.recognisers.kmeans_encoder import unit_rows  # noqa: E402
from servant_core.senses import AUDIO_SUFFIXES, PICTURE_SUFFIXES  # noqa: E402

WINDOW_S = wearer_day.WINDOW_S
STAY_S = 40.0
# the walk's windows of a recording: the taught ones and four stays after them
MAX_WINDOWS = TEACH_WINDOWS + 4 * int(STAY_S / WINDOW_S)
RECIPES = ("none", "gain", "eq", "shift", "mix", "all", "emb-mix", "emb-mid")
AUDIO_RECIPES = ("gain", "eq", "shift", "mix", "all")
KINDS = ("taught", "untaught", "taught kind")


@dataclass
class Recording:
    name: str
    scene: str
    path: Path
    X: np.ndarray  # (n, 1024) embeddings of its first windows
    first: int = 0  # the index of its first window among all recordings' windows
    augmented: dict[str, np.ndarray] = field(default_factory=dict)


def cached(path: Path, make: Any) -> np.ndarray:
    if path.is_file():
        return np.load(path)
    value = np.asarray(make(), dtype=np.float32)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npy")
    np.save(tmp, value)
    tmp.replace(path)
    return value


def windows_of(path: Path, rate: int, n: int) -> np.ndarray:
    """The first `n` windows of a recording at `rate` (fewer if it is shorter)."""
    audio = read_audio(path, rate)
    samples = int(rate * WINDOW_S)
    n = min(len(audio) // samples, n)
    return audio[: n * samples].reshape(n, samples)


def embedded(root: Path, model: BirdnetAcousticRecogniser, cache: Path) -> list[Recording]:
    """Every recording of `audio/dev` with its first `MAX_WINDOWS` windows embedded (cached)."""
    recordings = []
    paths = [
        p
        for p in sorted((root / "audio" / "dev").glob("*/*"))
        if p.suffix.lower() in AUDIO_SUFFIXES
    ]
    for i, path in enumerate(paths):
        key = f"{path.parent.name}--{path.name}"
        try:
            X = cached(
                cache / f"{key}.{model.rate}.base.npy",
                lambda path=path: model.featurize(windows_of(path, model.rate, MAX_WINDOWS)),
            )
        except ServantError as error:
            print(f"  left out: {error}")
            continue
        if len(X) >= 2:
            recordings.append(Recording(path.name, path.parent.name, path, X))
        print(f"\r  embedded {i + 1}/{len(paths)} recordings", end="", flush=True)
    print()
    first = 0
    for recording in recordings:
        recording.first = first
        first += len(recording.X)
    return recordings


def seed_of(*parts: str) -> np.random.Generator:
    return np.random.default_rng(list(hashlib.sha1("/".join(parts).encode()).digest()[:8]))


def equalised(window: np.ndarray, rate: int, rng: np.random.Generator) -> np.ndarray:
    """`window` through a drawn tilt and eight band gains (the module docstring's `eq`)."""
    spectrum = np.fft.rfft(window)
    f = np.maximum(np.fft.rfftfreq(len(window), 1 / rate), 20.0)
    octaves = np.log2(f / 1000.0)
    db = rng.uniform(-6, 6) * octaves / 3.0
    centres = np.log2(np.geomspace(50, 20000, 8) / 1000.0)
    db += np.interp(octaves, centres, rng.uniform(-6, 6, len(centres)))
    return np.fft.irfft(spectrum * 10 ** (db / 20), n=len(window)).astype(np.float32)


def mixed(window: np.ndarray, noises: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    noise = noises[rng.integers(len(noises))]
    power = float(np.mean(window.astype(np.float64) ** 2)) + 1e-12
    noise_power = float(np.mean(noise.astype(np.float64) ** 2)) + 1e-12
    snr_db = rng.uniform(5, 20)
    return (window + noise * np.sqrt(power / noise_power / 10 ** (snr_db / 10))).astype(np.float32)


def augmented_windows(
    recipe: str, taught: np.ndarray, rate: int, noises: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """The copies of `taught` (six consecutive windows, in order) that an audio recipe makes."""
    if recipe == "shift":
        audio = taught.reshape(-1)
        samples, half = taught.shape[1], taught.shape[1] // 2
        return np.stack(
            [audio[s : s + samples] for s in range(half, len(audio) - samples, samples)]
        )
    out = []
    copies = {"gain": 2, "eq": 3, "mix": 3, "all": 3}[recipe]
    for window in taught:
        for _ in range(copies):
            w = window
            if recipe in ("eq", "all"):
                w = equalised(w, rate, rng)
            if recipe in ("mix", "all"):
                w = mixed(w, noises, rng)
            if recipe in ("gain", "all"):
                w = w * np.float32(10 ** (rng.uniform(-12, 12) / 20))
            out.append(w)
    return np.stack(out)


class Augmenter:
    """Each recipe's copies of a recording's taught windows, embedded (cached)."""

    def __init__(
        self, model: BirdnetAcousticRecogniser, recordings: list[Recording], cache: Path
    ) -> None:
        self.model = model
        self.cache = cache
        self.background = background_embeddings(model)
        self.noise_paths = [r.path for r in recordings if wearer_day.in_background(r.name)]
        self._noises: np.ndarray | None = None

    def noises(self) -> np.ndarray:
        if self._noises is None:  # the first 30 s of each background recording
            self._noises = np.concatenate(
                [windows_of(p, self.model.rate, TEACH_WINDOWS) for p in self.noise_paths]
            )
        return self._noises

    def __call__(self, recording: Recording, recipe: str) -> np.ndarray:
        if recipe not in recording.augmented:
            recording.augmented[recipe] = self._make(recording, recipe)
        return recording.augmented[recipe]

    def _make(self, recording: Recording, recipe: str) -> np.ndarray:
        rng = seed_of(recording.scene, recording.name, recipe)
        taught = recording.X[:TEACH_WINDOWS]
        if recipe == "emb-mix":
            rows = np.repeat(taught, 3, axis=0).astype(np.float64)
            a = rng.uniform(0.1, 0.3, (len(rows), 1))
            b = self.background[rng.integers(len(self.background), size=len(rows))]
            return ((1 - a) * rows + a * b).astype(np.float32)
        if recipe == "emb-mid":
            return ((taught[1:].astype(np.float64) + taught[:-1]) / 2).astype(np.float32)
        key = f"{recording.scene}--{recording.name}.{self.model.rate}.{recipe}.npy"

        def make() -> np.ndarray:
            windows = windows_of(recording.path, self.model.rate, TEACH_WINDOWS)
            copies = augmented_windows(recipe, windows, self.model.rate, self.noises(), rng)
            return self.model.featurize(copies)

        return cached(self.cache / key, make)


def background_embeddings(model: BirdnetAcousticRecogniser) -> np.ndarray:
    found = model._background()
    if found is None:
        raise SystemExit("birdnet's background file is missing; nothing to measure")
    return found.frames.reshape(len(found.frames), -1).astype(np.float64)


def walk_data(root: Path, recordings: list[Recording], half: int) -> Any:
    """What `wearer_day.plan_walk` reads of its `Data`, with each window standing for its index
    among all recordings' windows (an (n, 1) array): the same draws, without the sound."""
    by_scene: dict[str, list[tuple[str, np.ndarray]]] = defaultdict(list)
    for r in recordings:
        if wearer_day.source_half(r.name) == half or wearer_day.in_background(r.name):
            by_scene[r.scene].append((r.name, np.arange(r.first, r.first + len(r.X))[:, None]))
    pictures = {
        folder.name: sorted(p for p in folder.iterdir() if p.suffix.lower() in PICTURE_SUFFIXES)
        for folder in sorted((root / "images" / "dev").iterdir())
        if folder.is_dir()
    }
    pictures = {scene: paths for scene, paths in pictures.items() if paths}
    both = sorted(
        s
        for s in pictures
        if any(not wearer_day.in_background(name) for name, _ in by_scene.get(s, []))
    )
    return SimpleNamespace(recordings=by_scene, pictures=pictures, both=both)


def unread(path: Any) -> Any:
    return path


def plan(data: Any, size: int, draw: int) -> dict[str, Any]:
    args = SimpleNamespace(shots=TEACH_WINDOWS, from_window=0, pictures=6, stay=STAY_S)
    real = wearer_day.read_picture
    wearer_day.read_picture = unread  # the draws without reading the pictures
    try:
        return wearer_day.plan_walk(data, size, args, np.random.default_rng([size, draw]))
    finally:
        wearer_day.read_picture = real


def fit(
    X: np.ndarray, scenes: np.ndarray, extra: np.ndarray, extra_scenes: np.ndarray, mode: str
) -> BirdnetAcousticRecogniser:
    """`birdnet` fitted on taught windows `X` and copies `extra` of them (one visit a place, as
    teach mode makes it), the copies `heard`, `derived` or for the acceptance only (`accept`;
    module docstring)."""
    model = BirdnetAcousticRecogniser()
    if mode == "accept":
        model.fit(X, scenes)
        taught = model._taught_rows
        copies = unit_rows(model._standardise(np.asarray(extra, dtype=np.float64)))

        def with_copies(place: str) -> np.ndarray:
            return np.vstack([taught(place), copies[np.asarray(extra_scenes) == place]])

        model._taught_rows = with_copies  # type: ignore[method-assign]
        return model
    model.fit(np.vstack([X, extra]), np.concatenate([scenes, extra_scenes]))
    if mode == "derived" and len(extra):
        model.train_derived_ = np.arange(len(model.train_scenes_)) >= len(X)
        model._fit_heads()
    return model


def measure_draw(
    p: dict[str, Any], recordings: list[Recording], augment: Augmenter, variants: list[str]
) -> dict[str, dict[str, tuple[int, int]]]:
    """{variant: {kind: (hits, windows)}} of one draw (module docstring)."""
    X_all = np.concatenate([r.X for r in recordings])
    owner = np.concatenate([np.full(len(r.X), i) for i, r in enumerate(recordings)])
    ids, y = p["audio"]
    ids = np.asarray(ids).reshape(-1)
    y = np.asarray(y).astype(str)
    taught_recordings = sorted({int(owner[i]) for i in ids})
    stays = [s for s in p["stays"] if s.kind in KINDS]
    stay_ids = np.concatenate([np.asarray(s.windows).reshape(-1) for s in stays])
    truth = np.concatenate([[s.truth or ""] * len(s.windows) for s in stays]).astype(str)
    kinds = np.concatenate([[s.kind] * len(s.windows) for s in stays])
    out = {}
    for variant in variants:
        recipe, _, mode = variant.partition("/")
        extra, extra_y = [np.empty((0, X_all.shape[1]))], [np.empty(0, dtype=str)]
        if recipe != "none":
            for i in taught_recordings:
                rows = augment(recordings[i], recipe)
                extra.append(rows)
                extra_y.append(np.full(len(rows), recordings[i].scene))
        model = fit(X_all[ids], y, np.concatenate(extra), np.concatenate(extra_y), mode)
        names = model.answers(X_all[stay_ids])[0]
        hit = np.where(kinds == "untaught", names != UNKNOWN, names == truth)
        out[variant] = {
            kind: (int(hit[kinds == kind].sum()), int((kinds == kind).sum())) for kind in KINDS
        }
    return out


def spread(values: list[float]) -> str:
    return f"{np.mean(values):.3f} ({min(values):.3f}-{max(values):.3f})"


def add_walk_options(parser: argparse.ArgumentParser) -> None:
    """The options every bench on these cached walks takes: the data, the library sizes, the
    draws a size and the cache of embedded windows."""
    parser.add_argument("--data", type=Path, default=shared_data())
    parser.add_argument("--sizes", default="2,3,5")
    parser.add_argument("--draws", type=int, default=6)
    parser.add_argument(
        "--cache",
        type=Path,
        default=Path(tempfile.gettempdir()) / "servant-teach-augment",
        help="where the embedded windows are kept between runs (default: %(default)s)",
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_walk_options(parser)
    parser.add_argument("--half", type=int, choices=(0, 1), required=True)
    parser.add_argument("--recipes", default=",".join(RECIPES))
    parser.add_argument(
        "--modes",
        default="heard,derived,accept",
        help="what the copies count for (module docstring; default: %(default)s)",
    )
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    if not (args.data / "audio" / "dev").is_dir():
        print(f"no real data at {args.data}; nothing to measure")
        return 0
    recipes = args.recipes.split(",")
    unknown = sorted(set(recipes) - set(RECIPES))
    if unknown:
        parser.error(f"unknown recipe {', '.join(unknown)}; choose among {', '.join(RECIPES)}")
    modes = args.modes.split(",")
    variants = [v for r in recipes for v in ([r] if r == "none" else [f"{r}/{m}" for m in modes])]
    start = time.time()
    model = BirdnetAcousticRecogniser()
    with library_noise_silenced():
        recordings = embedded(args.data, model, args.cache)
    augment = Augmenter(model, recordings, args.cache)
    data = walk_data(args.data, recordings, args.half)
    print(
        f"half {args.half}: {sum(len(v) for v in data.recordings.values())} recordings "
        f"(moodist-* among them, never walked), taught scenes drawn among {', '.join(data.both)}"
    )
    figures: dict[str, Any] = {}
    for size in [int(s) for s in args.sizes.split(",")]:
        per_draw: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
        for draw in range(args.draws):
            p = plan(data, size, draw)
            with library_noise_silenced():
                counts = measure_draw(p, recordings, augment, variants)
            for variant, by_kind in counts.items():
                for kind, (hits, n) in by_kind.items():
                    if n:
                        per_draw[variant][kind].append(hits / n)
            print(
                f"  {size} places, draw {draw}: {', '.join(p['taught'])} "
                f"({time.time() - start:.0f} s so far)",
                flush=True,
            )
        print(
            f"{size} places taught, half {args.half}, {args.draws} draws: mean (range over draws)"
        )
        print(f"  {'recipe':<18} {'right at taught':<22} {'wrong at untaught':<22} right at kind")
        for variant in variants:
            rates = per_draw[variant]
            print(f"  {variant:<18} " + " ".join(f"{spread(rates[k]):<22}" for k in KINDS))
        figures[str(size)] = {v: dict(k) for v, k in per_draw.items()}
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
