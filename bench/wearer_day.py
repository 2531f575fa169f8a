"""A wearer's day: a few places taught in teach mode, then a walk, through the live engine.

For each library size (2, 3 and 5 places) and each draw, places are drawn among the scenes that
have both recordings and pictures in `../shared/data`; each is taught as teach mode does: the
first `--shots` windows (5 s each; teach mode asks for six, `TEACH_WINDOWS`) of one of its
recordings and `--pictures` of its pictures.
The recognisers are Servant's defaults (`--audio-method`, `--image-method` to walk others),
fitted as a retrain fits them. Then the wearer walks through stays of `--stay` seconds, in a
random order:

- taught, same microphone: later windows of the taught recordings, with other pictures of the
  place's kind (never the taught ones);
- taught kind, another recording: the other recordings of the taught scenes;
- untaught: every recording of every scene not taught (beach, church, construction, crowd,
  forest, laundry, market, park and the picture scenes not drawn), with pictures of a picture
  scene not taught (gym has pictures and no recording: never taught).

The walk runs through the real `Engine` on a manual clock: the sound as 5 s windows from a
replayed recording, the camera as the stay's pictures every 2 s, the default fusion policy
(parallel), the live smoothing, the user's default confidence threshold (50 %), and an armed
arm. The arm is the one stand-in: a link object that is always armed and records each pose it is
sent (the serial path itself is tested on the emulator's pty in tests/test_live_path.py).

Recordings of the universal background (`moodist-*`, `servant_core/recognisers/background.py`)
are never taught and never walked through in the main figures: a place Servant ships as
"somewhere else" would flatter it. They are walked through separately, as "untaught, in the
background", for information.

Per library size it prints: the share of windows with a right move, a wrong move or none (by
kind of stay), wrong moves per hour of walking, seconds to the first right move in a taught
stay, and the share of untaught stays in which "What is this place?" was asked (and of taught
stays, where it should not be).

`--answers`: a wearer who answers every "What is this place?" the app shows (at most once a
minute, `PROMPT_EVERY_S`), at once, with the name of where they are: a taught place's name at it
and at another recording of its kind (another café is "cafe" too), an untaught place's kind (a
new place, with no pose: the arm never moves for it). Each answer goes through the engine's own
`label_unknown` (written to a throw-away library, folded into the model), so the rest of the walk
hears the grown model: what the learning loop does over a day. Without it the wearer never
answers: the first hours after teach mode.

    OMP_NUM_THREADS=1 python bench/wearer_day.py [--sizes 2,3,5] [--draws 3] [--shots N]
        [--from-window N] [--threshold PERCENT] [--audio-method NAME] [--answers] [--json FILE]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import statistics
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import add_arrive_sure, shared_data  # noqa: E402
from servant_core.audio import read_audio  # noqa: E402
from servant_core.capture.replay import Clip, PacedAudio  # noqa: E402
from servant_core.capture.source import ManualClock  # noqa: E402
from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.engine.core import Engine  # noqa: E402
from servant_core.engine.factories import live_policy, steady  # noqa: E402
from servant_core.errors import ServantError  # noqa: E402
from servant_core.events import UnknownScene  # noqa: E402
from servant_core.fusion.pipeline import ARRIVE_SURE  # noqa: E402
from servant_core.fusion.sequential import FusionConfig  # noqa: E402
from servant_core.library import TEACH_WINDOWS, read_picture  # noqa: E402
from servant_core.recognisers import FRESH_METHODS, make_recogniser  # noqa: E402
from servant_core.senses import AUDIO_SUFFIXES, PICTURE_SUFFIXES  # noqa: E402
from servant_core.settings import Settings  # noqa: E402
from servant_tui.app import PROMPT_EVERY_S  # noqa: E402  (how often the app asks)

BACKGROUND_PREFIX = "moodist-"
WINDOW_S = 5.0


@dataclass
class Stay:
    kind: str  # "taught", "taught kind", "untaught", "untaught, in the background"
    truth: str | None  # the taught place it is, None when untaught
    scene: str  # the folder of its recording: what a wearer asked "What is this place?" answers
    windows: np.ndarray  # (n, samples) at the model's rate
    pictures: list[np.ndarray]


class WalkCamera:
    """The pictures of the stay the walk is in, one after another as the engine asks."""

    name = "walk camera"

    def __init__(self, clock: ManualClock, stays: list[Stay]) -> None:
        self.clock = clock
        self.ends = np.cumsum([len(s.windows) * WINDOW_S for s in stays])
        self.stays = stays
        self.shown = 0

    def open(self) -> None:
        pass

    def read(self) -> np.ndarray:
        index = min(int(np.searchsorted(self.ends, self.clock(), side="right")), len(self.ends) - 1)
        pictures = self.stays[index].pictures
        self.shown += 1
        return pictures[self.shown % len(pictures)]

    def close(self) -> None:
        pass


class RecordingLink:
    """Stands in for the servo link: always armed, keeps each pose it is sent with the time.
    It is never "at its goal", so the engine sends it the decided place's pose at every window
    (a real arm standing at that pose is sent nothing): each window's decision is recorded."""

    armed = True
    at_goal = False
    port = None  # no serial port: the engine names it "link"

    def __init__(self, clock: ManualClock) -> None:
        self.clock = clock
        self.moves: list[tuple[float, str]] = []
        self.commanded: dict[str, float] = {}

    def move_to(self, pose: dict[str, str]) -> None:
        self.moves.append((self.clock(), pose["place"]))

    def status(self) -> None:
        return None

    def read_positions(self) -> None:
        return None


class Data:
    """The real recordings (their first windows, decoded once) and pictures, by scene."""

    def __init__(self, root: Path, rate: int, max_windows: int, half: int | None = None) -> None:
        self.rate = rate
        samples = int(rate * WINDOW_S)
        self.recordings: dict[str, list[tuple[str, np.ndarray]]] = defaultdict(list)
        for path in sorted((root / "audio" / "dev").glob("*/*")):
            if path.suffix.lower() not in AUDIO_SUFFIXES:
                continue
            if half is not None and source_half(path.name) != half and not in_background(path.name):
                continue
            try:
                audio = read_audio(path, rate)
            except ServantError as error:  # another library may hold a damaged file: not this one
                print(f"  left out: {error}")
                continue
            n = min(len(audio) // samples, max_windows)
            if n >= 2:
                windows = audio[: n * samples].reshape(n, samples)
                self.recordings[path.parent.name].append((path.name, windows))
        pictures = {
            folder.name: sorted(p for p in folder.iterdir() if p.suffix.lower() in PICTURE_SUFFIXES)
            for folder in sorted((root / "images" / "dev").iterdir())
            if folder.is_dir()
        }
        self.pictures = {scene: paths for scene, paths in pictures.items() if paths}
        self.both = sorted(
            s
            for s in self.pictures
            if len([r for r in self.recordings.get(s, []) if not in_background(r[0])]) >= 1
        )


def cannot_draw(data: Data, n_places: int, pictures: int) -> str | None:
    """Why a library of `n_places` cannot be drawn from `data` (None: it can): another library
    than ../shared may have fewer scenes with both sound and pictures, or none left untaught to
    show at untaught places."""
    if len(data.both) < n_places:
        return f"only {len(data.both)} scenes have both recordings and pictures"
    if len(data.pictures) <= n_places:
        return "no picture scene would be left untaught to show at untaught places"
    few = [s for s in data.both if len(data.pictures[s]) <= pictures]
    if few:
        return f"{', '.join(few)}: not more than {pictures} pictures, none left to walk with"
    return None


def source_half(name: str) -> int:
    """Which half of the sources a recording's source (its name up to the first `-`: the app
    or recorder) falls in, 0 or 1, by a hash of the name: the same halves on any machine."""
    source = name.split("-", 1)[0]
    return hashlib.sha1(source.encode("utf-8")).digest()[0] % 2


def in_background(name: str) -> bool:
    return name.startswith(BACKGROUND_PREFIX)


def pictures_of(paths: list[Path], rng: np.random.Generator, n: int) -> list[np.ndarray]:
    chosen = rng.choice(len(paths), min(n, len(paths)), replace=False)
    return [read_picture(paths[i]) for i in chosen]


def walk_from(args: Any) -> int:
    """The window of a taught recording its walk starts at: after the taught windows, or at
    `--from-window` (libraries taught for different lengths walked through the same windows)."""
    return max(args.shots, args.from_window or 0)


def plan_walk(data: Data, n_places: int, args: Any, rng: np.random.Generator) -> dict[str, Any]:
    """Draw the taught places and their teach-mode library, and the walk's stays."""
    taught = sorted(rng.choice(data.both, n_places, replace=False).tolist())
    stay_windows = int(round(args.stay / WINDOW_S))
    audio_X, audio_y, picture_X, picture_y = [], [], [], []
    stays: list[Stay] = []
    untaught_pictures = [s for s in data.pictures if s not in taught]
    for scene in taught:
        own = [r for r in data.recordings[scene] if not in_background(r[0])]
        name, windows = own[rng.integers(len(own))]
        audio_X.append(windows[: args.shots])
        audio_y += [scene] * len(windows[: args.shots])
        order = rng.permutation(len(data.pictures[scene]))
        paths = [data.pictures[scene][i] for i in order]
        picture_X += [read_picture(p) for p in paths[: args.pictures]]
        picture_y += [scene] * args.pictures
        later_paths = paths[args.pictures :]
        later = windows[walk_from(args) :]
        for start in range(0, len(later) - stay_windows + 1, stay_windows):
            stays.append(
                Stay(
                    "taught",
                    scene,
                    scene,
                    later[start : start + stay_windows],
                    pictures_of(later_paths, rng, 8),
                )
            )
        for other, other_windows in own:
            if other != name and len(other_windows) >= stay_windows:
                stays.append(
                    Stay(
                        "taught kind",
                        scene,
                        scene,
                        other_windows[:stay_windows],
                        pictures_of(later_paths, rng, 8),
                    )
                )
    for scene, recordings in data.recordings.items():
        if scene in taught:
            continue
        for name, windows in recordings:
            if len(windows) < stay_windows:
                continue
            looks = scene if scene in untaught_pictures else rng.choice(untaught_pictures)
            kind = "untaught, in the background" if in_background(name) else "untaught"
            stays.append(
                Stay(
                    kind,
                    None,
                    scene,
                    windows[:stay_windows],
                    pictures_of(data.pictures[looks], rng, 8),
                )
            )
    order = rng.permutation(len(stays))
    return {
        "taught": taught,
        "audio": (np.concatenate(audio_X), audio_y),
        "pictures": (picture_X, picture_y),
        "stays": [stays[i] for i in order],
    }


def walk(
    plan: dict[str, Any],
    rate: int,
    answering: bool = False,
    threshold: float | None = None,
    audio_method: str = FRESH_METHODS["audio"],
    accept_cosine: float | None = None,
    calibrated: bool = False,
    arrive_sure: float | None = ARRIVE_SURE,
    image_method: str = FRESH_METHODS["image"],
) -> dict[str, Any]:
    """Teach, then walk through the engine; what happened in each stay. `answering`: the wearer
    answers "What is this place?" (`--answers`); `threshold`: the arm's confidence threshold in
    percent (None: the user's default); `audio_method`: the sound's recogniser;
    `accept_cosine`: a fixed nearest-taught-window cosine (None: the method's own);
    `calibrated`: each place's acceptance calibrated by the background instead; `arrive_sure`:
    the probability at which one sound window alone names a place arriving (None: never);
    `image_method`: the pictures' recogniser."""
    audio = make_recogniser("audio", audio_method)
    if accept_cosine is not None:  # another fixed acceptance than the method's
        audio.accept_cosine = accept_cosine
    if calibrated:  # each place's acceptance from the background (issue 37)
        audio.calibrated_accept = True
    audio.featurize = remembered(audio.featurize)  # type: ignore[method-assign]
    X, y = plan["audio"]
    audio.fit(audio.featurize(X), y)
    visual = make_recogniser("image", image_method)
    pictures, labels = plan["pictures"]
    visual.fit(visual.featurize(pictures), labels)
    stays: list[Stay] = plan["stays"]
    clock = ManualClock()
    clips = [Clip(s.truth, w) for s in stays for w in s.windows]
    source = PacedAudio(clips, rate, realtime=False, clock=clock)
    camera = WalkCamera(clock, stays)
    user = Settings()
    engine = Engine(
        audio=source,
        camera=camera,
        acoustic=audio,
        visual=visual,
        fusion=live_policy("parallel", FusionConfig()),
        clock=clock,
        confidence_threshold=user.confidence_threshold if threshold is None else threshold,
        smoother=steady(),
    )
    engine.decisions.arrive_sure = arrive_sure
    link = RecordingLink(clock)
    engine.set_arm(link)  # the stand-in link (see the module docstring)
    # a pose for each taught place; a place only labelled has none, as in the app
    taught = set(plan["taught"])
    engine.set_action_learner(
        lambda scene, scores, confidence: {"place": scene} if scene in taught else None
    )
    asked: list[UnknownScene] = []
    engine.subscribe(
        lambda e: asked.append(e) if isinstance(e, UnknownScene) and e.sense == "audio" else None
    )
    starts = np.concatenate([[0.0], np.cumsum([len(s.windows) * WINDOW_S for s in stays])])
    total = float(starts[-1])
    answers: list[tuple[float, str]] = []
    with tempfile.TemporaryDirectory() as library:
        engine.library_root = Path(library)  # where the answers are written, as in the app
        for end in [*starts[1:], total + 0.5]:
            engine.run_until(end)
            if answering:
                answers += answer(engine, asked, answers, stays, starts)
    engine.stop()
    times = [e.t for e in asked]
    out = []
    for i, stay in enumerate(stays):
        begin, end = starts[i], starts[i + 1]
        moves = [(t, place) for t, place in link.moves if begin < t <= end + 1e-6]
        per_window = []
        for w in range(len(stay.windows)):
            lo, hi = begin + w * WINDOW_S, begin + (w + 1) * WINDOW_S
            here = [p for t, p in moves if lo < t <= hi + 1e-6]
            if not here:
                per_window.append("none")
            elif all(p == stay.truth for p in here):
                per_window.append("right")
            else:
                per_window.append("wrong")
        first_right = next((t - begin for t, p in moves if p == stay.truth), None)
        out.append(
            {
                "kind": stay.kind,
                "scene": stay.scene,
                "windows": per_window,
                "first_right_s": first_right,
                "asked": any(begin < t <= end + 1e-6 for t in times),
                # not about the last place's windows: after the stay's first two windows
                "asked_late": any(begin + 2 * WINDOW_S < t <= end + 1e-6 for t in times),
                "answered": [name for t, name in answers if begin < t <= end + 1e-6],
            }
        )
    return {"stays": out, "hours": total / 3600}


# Each window's features by its bytes, kept across draws: `featurize` depends only on the method's
# parameters (recognisers.base), and every draw walks through the same recordings' windows, so a
# window is featurized once a run (`birdnet` takes 0.1 s a window: most of a draw's time).
FEATURES: dict[tuple[str, bytes], np.ndarray] = {}


def remembered(featurize: Any) -> Any:
    def featurize_once(windows: np.ndarray) -> np.ndarray:
        windows = np.asarray(windows, dtype=np.float32)
        owner = type(featurize.__self__).__name__
        keys = [(owner, hashlib.sha1(w.tobytes()).digest()) for w in windows]
        missing = [i for i, k in enumerate(keys) if k not in FEATURES]
        if missing:
            for i, row in zip(missing, featurize(windows[missing]), strict=True):
                FEATURES[keys[i]] = row
        return np.stack([FEATURES[k] for k in keys])

    return featurize_once


def answer(
    engine: Engine,
    asked: list[UnknownScene],
    answered: list[tuple[float, str]],
    stays: list[Stay],
    starts: np.ndarray,
) -> list[tuple[float, str]]:
    """A wearer who answers: the newest question about the sound, if the app would show it (at
    most once every `PROMPT_EVERY_S`), is answered at once with the name of the place the wearer
    is in: a taught place's own name (also at another café when a café is taught), an untaught
    place's kind (a new place, with no pose). Returns the answers given ((time, name))."""
    if not asked:
        return []
    newest = asked[-1]
    if answered and newest.t - answered[-1][0] < PROMPT_EVERY_S:
        return []
    stay = stays[min(int(np.searchsorted(starts, newest.t, side="left")) - 1, len(stays) - 1)]
    engine.label_unknown(newest.window_id, stay.scene)
    return [(newest.t, stay.scene)]


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    by_kind: dict[str, dict[str, int]] = defaultdict(lambda: defaultdict(int))
    asked: dict[str, list[bool]] = defaultdict(list)
    asked_late: dict[str, list[bool]] = defaultdict(list)
    answered: dict[str, int] = defaultdict(int)
    first: list[float] = []
    never = 0
    wrong_moves, hours = 0, 0.0
    for run in runs:
        hours += run["hours"]
        for stay in run["stays"]:
            for outcome in stay["windows"]:
                by_kind[stay["kind"]][outcome] += 1
            wrong_moves += stay["windows"].count("wrong")
            asked[stay["kind"]].append(stay["asked"])
            asked_late[stay["kind"]].append(stay["asked_late"])
            answered[stay["kind"]] += len(stay["answered"])
            if stay["kind"] == "taught":
                if stay["first_right_s"] is None:
                    never += 1
                else:
                    first.append(stay["first_right_s"])
    shares = {
        kind: {o: counts[o] / max(sum(counts.values()), 1) for o in ("right", "wrong", "none")}
        | {"windows": sum(counts.values())}
        for kind, counts in by_kind.items()
    }
    # the same, leaving out each stay's first two windows (a place is named when two windows in
    # a row say so): what recognition does once the wearer is there, apart from arriving
    settled = [
        w
        for run in runs
        for stay in run["stays"]
        if stay["kind"] == "taught"
        for w in stay["windows"][2:]
    ]
    return {
        "shares": shares,
        "wrong_moves_per_hour": wrong_moves / hours if hours else 0.0,
        "first_right_median_s": statistics.median(first) if first else None,
        "first_right_within_10s": float(np.mean([f <= 10 for f in first])) if first else None,
        "taught_stays_without_a_right_move": never,
        "right_after_10s": settled.count("right") / max(len(settled), 1),
        "asked": {kind: float(np.mean(v)) for kind, v in asked.items()},
        "asked_late": {kind: float(np.mean(v)) for kind, v in asked_late.items()},
        "answered": dict(answered),
    }


def report(result: dict[str, Any], answers: bool) -> None:
    """Print one library size's figures (`summarise`'s)."""
    for kind, share in sorted(result["shares"].items()):
        print(
            f"  {kind:<28} windows {share['windows']:>5}  right {share['right']:.3f}  "
            f"wrong {share['wrong']:.3f}  none {share['none']:.3f}  "
            f"asked in {result['asked'][kind]:.2f} of stays "
            f"({result['asked_late'][kind]:.2f} after their first 10 s)"
            + (f", answered {result['answered'].get(kind, 0)}" if answers else "")
        )
    print(
        f"  wrong moves per hour of walking {result['wrong_moves_per_hour']:.1f}; first right "
        f"move in a taught stay after {result['first_right_median_s'] or float('nan'):.1f} s "
        f"(median), within 10 s in {result['first_right_within_10s'] or 0.0:.2f} of them, "
        f"{result['taught_stays_without_a_right_move']} taught stays with none; right "
        f"moves in taught stays after their first 10 s: {result['right_after_10s']:.3f}"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data())
    parser.add_argument("--sizes", default="2,3,5")
    parser.add_argument("--draws", type=int, default=3)
    parser.add_argument(
        "--shots",
        type=int,
        default=TEACH_WINDOWS,
        help="windows taught a place (default: what teach mode asks for)",
    )
    parser.add_argument(
        "--from-window",
        type=int,
        default=0,
        help="taught stays start at this window of the recording (default: after the taught ones)",
    )
    parser.add_argument("--pictures", type=int, default=6, help="pictures taught a place")
    parser.add_argument("--stay", type=float, default=40.0, help="seconds a stay lasts")
    parser.add_argument("--json", type=Path)
    parser.add_argument(
        "--threshold",
        type=float,
        help="the arm's confidence threshold in percent (default: the Settings default)",
    )
    parser.add_argument(
        "--audio-method",
        default=FRESH_METHODS["audio"],
        help="the sound's recogniser (default: what a retrain fits, %(default)s)",
    )
    parser.add_argument(
        "--image-method",
        default=FRESH_METHODS["image"],
        help="the pictures' recogniser (default: what a retrain fits, %(default)s)",
    )
    parser.add_argument(
        "--half",
        type=int,
        choices=(0, 1),
        help="walk the recordings of one half of the sources only (`source_half`): constants "
        "chosen on one half, walked on the other",
    )
    parser.add_argument(
        "--accept-cosine",
        type=float,
        help="birdnet: another fixed nearest-taught-window cosine than its own (0.5)",
    )
    parser.add_argument(
        "--calibrated-accept",
        action="store_true",
        help="birdnet: each place's acceptance from the background instead of the fixed cosine",
    )
    add_arrive_sure(parser, several=True)
    parser.add_argument(
        "--answers",
        action="store_true",
        help='the wearer answers "What is this place?" with its name (at most once a minute)',
    )
    args = parser.parse_args()
    if not (args.data / "audio" / "dev").is_dir():
        print(f"no real data at {args.data}; nothing to measure")
        return 0
    rate = make_recogniser("audio", args.audio_method).rate
    start = time.time()
    with library_noise_silenced():
        data = Data(args.data, rate, walk_from(args) + 4 * int(args.stay / WINDOW_S), args.half)
    print(
        f"{sum(len(r) for r in data.recordings.values())} recordings, scenes with pictures and "
        f"sound: {', '.join(data.both)}; {args.draws} draws a size, {args.shots} windows and "
        f"{args.pictures} pictures a place, stays of {args.stay:g} s, sound by "
        f"{args.audio_method}, pictures by {args.image_method}"
        + ("" if args.half is None else f", sources of half {args.half} only")
        + "; one window alone names a place at "
        + ", ".join(str(p or "never") for p in args.arrive_alone)
    )
    figures = {}
    for sure in args.arrive_alone:
        if len(args.arrive_alone) > 1:
            print(f"one window alone names a place at {sure or 'never'}:")
        for size in [int(s) for s in args.sizes.split(",")]:
            why = cannot_draw(data, size, args.pictures)
            if why:
                print(f"{size} places taught: left out, {why}")
                continue
            runs = []
            for draw in range(args.draws):
                plan = plan_walk(data, size, args, np.random.default_rng([size, draw]))
                with library_noise_silenced():
                    runs.append(
                        walk(
                            plan,
                            rate,
                            args.answers,
                            args.threshold,
                            args.audio_method,
                            args.accept_cosine,
                            args.calibrated_accept,
                            sure,
                            args.image_method,
                        )
                    )
                print(f"  {size} places, draw {draw}: {', '.join(plan['taught'])}", flush=True)
            result = summarise(runs)
            figures[size if len(args.arrive_alone) == 1 else f"{size}@{sure}"] = {
                **result,
                "runs": runs,
            }
            print(f"{size} places taught ({time.time() - start:.0f} s so far):")
            report(result, args.answers)
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
