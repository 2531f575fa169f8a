"""Why `birdnet`'s head loses to a plain logistic regression on the same embeddings (issue 37).

On `tut2017` (leave one recording location out, `bench/peers.py --protocols source`'s folds),
every variant scores the same cached windows through `evaluate_windows`: the product's own
`BirdnetAcousticRecogniser` with one thing changed at a time, and plain logistic regressions.
A variant's C (and temperature), where it says "cv", is chosen inside each training fold by
cross-validation grouped by location, never on the test location.

Every `birdnet` variant but the default's own row is the visit head alone (`place_share` 0, the
default before issue 37) with one thing changed. `--taught` scores the same variants on a
wearer's library (`--audio ../shared/data/audio/dev`): temporal, few-shot and source columns.

    OMP_NUM_THREADS=1 python bench/tut2017_head.py [--audio ../shared/data/audio/tut2017]
        [--cache /tmp/servant-tut2017] [--variants "one class a place,plain LR C 0.1"]
        [--draws 4] [--taught] [--json FILE]

The windows are embedded once (BirdNET at 48 kHz, `kmeans-encoder`'s log-mel frame statistics
at 22,050 Hz) and kept in `--cache`, outside the repository: nothing fitted here is kept.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, ClassVar, Self, cast

import numpy as np
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import GroupKFold
from sklearn.preprocessing import StandardScaler

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import shared_data  # noqa: E402

from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.evaluate import (  # noqa: E402
    AudioPlan,
    audio_plans,
    evaluate_windows,
    source_of,
)
from servant_core.library import SceneLibrary, WindowFeatures, iter_recording_windows  # noqa: E402
from servant_core.recognisers import Recogniser  # noqa: E402
from servant_core.recognisers.background import kept_out  # noqa: E402
from servant_core.recognisers.base import TaughtPlacesOnly, fit_visits  # noqa: E402
from servant_core.recognisers.birdnet import (  # noqa: E402
    BIRDNET_RATE,
    PLACE_SHARE,
    BirdnetAcousticRecogniser,
)
from servant_core.recognisers.encoder_features import frame_statistics  # noqa: E402
from servant_core.recognisers.kmeans_encoder import (  # noqa: E402
    ENCODER_RATE,
    KMeansEncoderAcousticRecogniser,
)
from servant_core.recognisers.visit_head import place_proba, softmax_proba  # noqa: E402

WINDOW_SECONDS = 5.0


def cached_features(audio: Path, cache: Path) -> tuple[SceneLibrary, dict[str, np.ndarray]]:
    """Every window's BirdNET embedding (48 kHz) and log-mel frame statistics (22,050 Hz), with
    its scene, recording and position; read from `cache` when it holds them."""
    library = SceneLibrary.scan(audio)
    path = cache / "windows.npz"
    names = np.array([str(r.path.relative_to(library.root)) for r in library.recordings])
    if path.is_file():
        with np.load(path) as data:
            if np.array_equal(data["names"], names):
                return library, {k: data[k] for k in data.files}
    parts: dict[str, list[np.ndarray]] = {"birdnet": [], "stats": []}
    scenes: list[str] = []
    recording: list[int] = []
    position: list[int] = []
    birdnet = BirdnetAcousticRecogniser()
    encoder = KMeansEncoderAcousticRecogniser()
    for rate, key, featurize in (
        (BIRDNET_RATE, "birdnet", birdnet.featurize),
        (ENCODER_RATE, "stats", lambda w: frame_statistics(encoder.featurize(w))),
    ):
        for index, rec, windows in iter_recording_windows(library.recordings, rate, WINDOW_SECONDS):
            parts[key].append(np.asarray(featurize(windows), dtype=np.float32))
            if key == "birdnet":
                scenes += [rec.scene] * len(windows)
                recording += [index] * len(windows)
                position += range(len(windows))
            print(f"  {key} {index + 1}/{len(library.recordings)}", file=sys.stderr, end="\r")
    arrays = {
        "names": names,
        "birdnet": np.concatenate(parts["birdnet"]),
        "stats": np.concatenate(parts["stats"]),
        "scenes": np.array(scenes),
        "recording": np.array(recording),
        "position": np.array(position),
    }
    cache.mkdir(parents=True, exist_ok=True)
    np.savez(path, **arrays)  # type: ignore[arg-type]
    return library, arrays


class Birdnet(BirdnetAcousticRecogniser):
    """`birdnet` as the product has it, but for the one thing a variant changes: a place scored
    by its visits summed (`together`), no novelty head's `UNKNOWN` in `predict` (`unknown`)."""

    def __init__(self, *, together: bool = False, unknown: bool = True, **params: Any) -> None:
        super().__init__(**params)
        self.together = together
        self.unknown = unknown

    def _proba(self, D: np.ndarray) -> np.ndarray:
        if not self.together:
            return super()._proba(D)
        proba = softmax_proba((D @ self.coef_.T + self.intercept_) / self.temperature)
        places = place_proba(proba, self.mode_scenes_, self.classes_, together=True)
        return places / places.sum(axis=1, keepdims=True)

    def _names(self, D: np.ndarray) -> np.ndarray:
        if self.unknown:
            return super()._names(D)
        return np.asarray(self.scenes_, dtype=object)[np.argmax(self._proba(D), axis=1)]


class PlainLR(TaughtPlacesOnly):
    """Standardised rows, a multinomial logistic regression with balanced class weights."""

    def __init__(self, C: float) -> None:
        self.C = C

    def fit(self, X: np.ndarray, scenes: np.ndarray) -> Self:
        self.scale_ = StandardScaler().fit(X)
        self.head_ = LogisticRegression(C=self.C, class_weight="balanced", max_iter=3000)
        self.head_.fit(self.scale_.transform(X), scenes)
        return self

    @property
    def scenes_(self) -> list[str]:
        return [str(s) for s in self.head_.classes_]

    def predict(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(self.head_.predict(self.scale_.transform(X)))

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(self.head_.predict_proba(self.scale_.transform(X)))


class Variant(TaughtPlacesOnly):
    """A recogniser of rows [BirdNET embedding | frame statistics | location]: `make(params)`
    fitted on the `columns` it reads, each place's visits its clips (`clip`, what
    `library.visits_of` gives), its locations (`location`) or one a place (`place`). Parameters
    in `search` are chosen inside the training rows by cross-validation grouped by location:
    C by balanced accuracy, then the temperature (set after fitting) by log loss."""

    learns_visits: ClassVar[bool] = True

    def __init__(
        self,
        make: Callable[[dict[str, Any]], Any],
        columns: slice,
        visits: str = "clip",
        search: dict[str, list[float]] | None = None,
    ) -> None:
        self.make = make
        self.columns = columns
        self.visits = visits
        self.search = search or {}

    def _visits(self, X: np.ndarray, visits: np.ndarray | None) -> np.ndarray | None:
        return {"clip": visits, "location": X[:, -1], "place": None}[self.visits]

    def fit(self, X: np.ndarray, scenes: np.ndarray, visits: np.ndarray | None = None) -> Self:
        scenes = np.asarray(scenes).astype(str)
        self.chosen_ = self._searched(X, scenes, visits) if self.search else {}
        temperature = self.chosen_.pop("temperature", None)
        self.model_ = fit_visits(
            self.make(self.chosen_), X[:, self.columns], scenes, self._visits(X, visits)
        )
        if temperature is not None:
            self.model_.temperature = temperature
            self.chosen_["temperature"] = temperature
        return self

    def _searched(
        self, X: np.ndarray, scenes: np.ndarray, visits: np.ndarray | None
    ) -> dict[str, Any]:
        location = X[:, -1]
        folds = list(GroupKFold(INNER_FOLDS).split(X, scenes, location))
        temperatures = self.search.get("temperature", [None])
        found: dict[tuple[Any, Any], list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
        for C in self.search.get("C", [None]):
            params = {} if C is None else {"C": C}
            for train, test in folds:
                model = fit_visits(
                    self.make(params),
                    X[train][:, self.columns],
                    scenes[train],
                    None if visits is None else self._visits(X[train], visits[train]),
                )
                column = {s: j for j, s in enumerate(model.scenes_)}
                truth = np.array([column.get(s, -1) for s in scenes[test]])
                for t in temperatures:
                    if t is not None:
                        model.temperature = t
                    proba = model.predict_proba(X[test][:, self.columns])
                    found.setdefault((C, t), []).append((scenes[test], truth, proba))
        figures = {key: inner_scores(parts) for key, parts in found.items()}
        best_C = max(
            self.search.get("C", [None]),
            key=lambda C: max(figures[(C, t)][0] for t in temperatures),
        )
        best_t = min(temperatures, key=lambda t: figures[(best_C, t)][1])
        chosen: dict[str, Any] = {}
        if best_C is not None:
            chosen["C"] = best_C
        if best_t is not None:
            chosen["temperature"] = best_t
        return chosen

    @property
    def scenes_(self) -> list[str]:
        return [str(s) for s in self.model_.scenes_]

    def predict(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(self.model_.predict(X[:, self.columns]))

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        return np.asarray(self.model_.predict_proba(X[:, self.columns]))


INNER_FOLDS = 3


def inner_scores(parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> tuple[float, float]:
    """(balanced accuracy, log loss) of an inner search's held-out rows, each part (their scenes,
    their scene's column in the model's probabilities or -1 where it did not learn that scene,
    the probabilities)."""
    scenes = np.concatenate([part[0] for part in parts])
    right = np.concatenate([np.argmax(part[2], axis=1) == part[1] for part in parts])
    p = np.concatenate(
        [np.where(t >= 0, proba[np.arange(len(t)), np.maximum(t, 0)], 0.0) for _, t, proba in parts]
    )
    recall = [np.mean(right[scenes == s]) for s in np.unique(scenes)]
    return float(np.mean(recall)), float(-np.mean(np.log(np.clip(p, 1e-15, 1.0))))


EMBEDDING = slice(0, 1024)
WITH_STATISTICS = slice(0, 1024 + 192)
C_GRID = [0.01, 0.1, 1.0]
TEMPERATURES = [0.5, 1.0, 1.5, 2.0, 3.0]


def variants(library: SceneLibrary) -> dict[str, Callable[[], Variant]]:
    """Every variant by name: the product's head with one thing changed, and the plain ones."""

    def birdnet(**fixed: Any) -> Callable[[dict[str, Any]], Any]:
        """The product's `birdnet`, its visit head alone (no place head mixed in) unless said."""
        return lambda params: kept_out(
            Birdnet(**{"place_share": 0.0, **fixed, **params}), library.recordings
        )

    def plain(C: float | None = None) -> Callable[[dict[str, Any]], Any]:
        return lambda params: PlainLR(**({"C": C} if C is not None else params))

    cv_c = {"C": C_GRID}
    cv_ct = {"C": C_GRID, "temperature": TEMPERATURES}
    return {
        "visit head (the default before)": lambda: Variant(birdnet(), EMBEDDING),
        "visit and place heads averaged (the default)": lambda: Variant(
            birdnet(place_share=PLACE_SHARE), EMBEDDING
        ),
        "averaged; C and T by inner cv": lambda: Variant(
            birdnet(place_share=PLACE_SHARE), EMBEDDING, search=cv_ct
        ),
        "no novelty UNKNOWN": lambda: Variant(birdnet(unknown=False), EMBEDDING),
        "visits summed": lambda: Variant(birdnet(together=True), EMBEDDING),
        "visits = locations": lambda: Variant(birdnet(), EMBEDDING, "location"),
        "one class a place": lambda: Variant(birdnet(), EMBEDDING, "place"),
        "no <elsewhere>": lambda: Variant(birdnet(background=False), EMBEDDING),
        "C 0.01 (diagnostic)": lambda: Variant(birdnet(C=0.01), EMBEDDING),
        "C 1 (diagnostic)": lambda: Variant(birdnet(C=1.0), EMBEDDING),
        "C and T by inner cv": lambda: Variant(birdnet(), EMBEDDING, search=cv_ct),
        "place; C and T by inner cv": lambda: Variant(birdnet(), EMBEDDING, "place", cv_ct),
        "place; summed; no UNKNOWN": lambda: Variant(
            birdnet(together=True, unknown=False), EMBEDDING, "place"
        ),
        "plain LR C 0.1": lambda: Variant(plain(0.1), EMBEDDING),
        "plain LR C inner cv": lambda: Variant(plain(), EMBEDDING, search=cv_c),
        "plain LR +stats C inner cv": lambda: Variant(plain(), WITH_STATISTICS, search=cv_c),
    }


def one_location_plans(
    scenes: np.ndarray, location: np.ndarray, draws: int, seed: int = 0
) -> list[AudioPlan]:
    """Each draw: the windows of one location a scene train, every other window tests."""
    rng = np.random.default_rng(seed)
    plans = []
    for _ in range(draws):
        train = np.zeros(len(scenes), dtype=bool)
        for scene in np.unique(scenes):
            here = np.unique(location[scenes == scene])
            train |= (scenes == scene) & (location == rng.choice(here))
        plans.append(AudioPlan("one location", [train], [~train]))
    return plans


def location_spread(
    row: dict[str, Any], resamples: int = 200, seed: int = 0
) -> tuple[float, float]:
    """(std of the per-location accuracy, std of the balanced accuracy over bootstrap resamples of
    the locations) from a row's `per_recording`."""
    by_location: dict[str, list[tuple[str, int, int]]] = {}
    for name, rec in row["per_recording"].items():
        n = sum(rec["heard_as"].values())
        right = rec["heard_as"].get(rec["scene"], 0)
        by_location.setdefault(source_of(Path(name)), []).append((rec["scene"], right, n))
    locations = sorted(by_location)
    per_location = [
        sum(r for _, r, _ in by_location[g]) / sum(n for _, _, n in by_location[g])
        for g in locations
    ]
    rng = np.random.default_rng(seed)
    figures = []
    for _ in range(resamples):
        hits: dict[str, int] = {}
        total: dict[str, int] = {}
        for g in rng.choice(locations, len(locations)):
            for scene, r, n in by_location[str(g)]:
                hits[scene] = hits.get(scene, 0) + r
                total[scene] = total.get(scene, 0) + n
        figures.append(np.mean([hits[s] / total[s] for s in total]))
    return float(np.std(per_location)), float(np.std(figures))


def run(name: str, make: Callable[[], Variant], wf: WindowFeatures, draws: int) -> dict[str, Any]:
    names = [str(r.path) for r in wf.recordings]
    location = wf.features[:, -1]
    made_here: list[Variant] = []

    def made(seed: int | None) -> Recogniser:
        del seed
        made_here.append(make())
        return cast(Recogniser, made_here[-1])

    start = time.perf_counter()
    (row,) = evaluate_windows(wf, names, audio_plans(wf, "source"), made)
    per_location_std, bootstrap_std = location_spread(row)
    chosen = [dict(getattr(v, "chosen_", {})) for v in made_here]
    few = evaluate_windows(wf, names, one_location_plans(wf.scenes, location, draws), made)
    return {
        "variant": name,
        "balanced_accuracy": row["balanced_accuracy"],
        "log_loss": row["log_loss"],
        "unknown_rate": row["unknown_rate"],
        "bootstrap_std": bootstrap_std,
        "per_location_std": per_location_std,
        "one_location": [r["balanced_accuracy"] for r in few],
        "chosen": [c for c in chosen if c],
        "seconds": time.perf_counter() - start,
    }


def run_taught(name: str, make: Callable[[], Variant], wf: WindowFeatures) -> dict[str, Any]:
    """A wearer's library's protocols (`--taught`): temporal, few-shot k = 1, 3, 10 (the same
    recordings' later windows) and source over the scenes with three recordings or more."""
    names = [str(r.path) for r in wf.recordings]

    def made(seed: int | None) -> Recogniser:
        del seed
        return cast(Recogniser, make())

    start = time.perf_counter()
    plans = audio_plans(wf, "temporal") + audio_plans(wf, "fewshot", (1, 3, 10))
    rows = evaluate_windows(wf, names, plans, made)
    per_scene = {s: len(np.unique(wf.recording[wf.scenes == s])) for s in set(wf.scenes)}
    several = np.array([per_scene[s] >= 3 for s in wf.scenes])
    kept = WindowFeatures(
        wf.features[several],
        wf.scenes[several],
        wf.recording[several],
        wf.position[several],
        wf.recordings,
    )
    rows += evaluate_windows(kept, names, audio_plans(kept, "source"), made)
    columns = ["temporal", "k=1", "k=3", "k=10", "source"]
    return {
        "variant": name,
        **{c: (r["balanced_accuracy"], r["log_loss"]) for c, r in zip(columns, rows, strict=True)},
        "seconds": time.perf_counter() - start,
    }


def table_row(r: dict[str, Any]) -> str:
    one = r["one_location"]
    return (
        f"| {r['variant']} | {r['balanced_accuracy']:.3f} ± {r['bootstrap_std']:.3f} "
        f"| {r['per_location_std']:.3f} | {r['log_loss']:.2f} | {r['unknown_rate']:.3f} "
        f"| {np.mean(one):.3f} ({min(one):.3f}–{max(one):.3f}) "
        f"| {chosen_text(r['chosen'])} |"
    )


def chosen_text(chosen: list[dict[str, Any]]) -> str:
    counts: dict[str, int] = {}
    for c in chosen:
        key = " ".join(f"{k}={v:g}" for k, v in sorted(c.items()))
        counts[key] = counts.get(key, 0) + 1
    return ", ".join(f"{k} ×{n}" for k, n in sorted(counts.items(), key=lambda kv: -kv[1])[:3])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--audio", type=Path, default=shared_data() / "audio" / "tut2017")
    parser.add_argument("--cache", type=Path, default=Path("/tmp/servant-tut2017"))
    parser.add_argument("--variants", type=lambda text: text.split(","), help="names, comma")
    parser.add_argument("--draws", type=int, default=4, help="one-location draws")
    parser.add_argument("--json", type=Path, help="also write every row here")
    parser.add_argument(
        "--taught",
        action="store_true",
        help="a wearer's library (DATA/audio/dev): temporal, few-shot and source columns",
    )
    args = parser.parse_args()
    library, arrays = cached_features(args.audio, args.cache)
    sources = sorted({source_of(r.path) for r in library.recordings})
    number = np.array([sources.index(source_of(r.path)) for r in library.recordings], float)
    features = np.hstack([arrays["birdnet"], arrays["stats"], number[arrays["recording"]][:, None]])
    wf = WindowFeatures(
        features, arrays["scenes"], arrays["recording"], arrays["position"], library.recordings
    )
    every = variants(library)
    chosen = args.variants or list(every)
    unknown = set(chosen) - set(every)
    if unknown:
        parser.error(f"no variant {', '.join(sorted(unknown))}; choose from {', '.join(every)}")
    if args.taught:
        taught_table(wf, every, chosen, args.json)
        return
    rows = []
    for name in chosen:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # inner folds missing a scene warn
            rows.append(run(name, every[name], wf, args.draws))
        print(f"  {table_row(rows[-1])} {rows[-1]['seconds']:.0f} s", file=sys.stderr, flush=True)
    print(
        "| variant | balanced accuracy (± bootstrap over locations) | per-location std "
        "| log loss | unknown | one location a scene, mean (min–max) | chosen inside folds |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(table_row(r))
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1, default=str))


def taught_table(
    wf: WindowFeatures, every: dict[str, Callable[[], Variant]], chosen: list[str], out: Path | None
) -> None:
    rows = []
    for name in chosen:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rows.append(run_taught(name, every[name], wf))
        print(f"  {name}: {rows[-1]['seconds']:.0f} s", file=sys.stderr, flush=True)
    columns = ["temporal", "k=1", "k=3", "k=10", "source"]
    print("| variant | " + " | ".join(columns) + " |")
    print("|---|" + "---|" * len(columns))
    for r in rows:
        cells = [f"{r[c][0]:.3f} ({r[c][1]:.2f})" for c in columns]
        print(f"| {r['variant']} | " + " | ".join(cells) + " |")
    if out:
        out.write_text(json.dumps(rows, indent=1, default=str))


if __name__ == "__main__":
    with library_noise_silenced():
        main()
