"""How long a wearer waits, from walking into a taught place to the arm's move to its pose.

Each draw teaches `--places` places as teach mode does (the first six 5 s windows of one of the
place's recordings, `TEACH_WINDOWS`, and six of its pictures), with Servant's default
recognisers (`birdnet`, `fisher-bovw`) fitted as a retrain fits them. Then, through the real
`Engine` on a manual clock (the default parallel fusion policy, the live steadying, the 50 %
threshold of the settings, an armed arm), each trial plays somewhere else for a while — an
untaught place (a recording of a scene not taught) or another taught place (its later minutes) —
and switches to a taught place's later minutes (the same microphone as taught, never the taught
windows) at a random moment: the microphone's 5 s windows do not line up with the moment the
wearer walks in, so the switch falls at a uniformly drawn offset within the window cycle. The
camera switches with the sound, from the place before's pictures to other pictures of the
taught place (never the taught ones), one every 2 s as the policy asks.

It measures, in the engine's time (what the wearer waits, the microphone's pace), the seconds
from the switch to the arm's first move command for that place's pose, and prints their median,
quartiles and the share within 10 s, and where the time goes: the wait for the first whole 5 s
window of the place, the sound's naming of it (the first window that names it alone, and the
first once held steady: two windows in a row, `steady_open`), the fusion's decision (with the
pictures of the last `confirm_window_s`) and the move. The arm's settle (its joints' speeds
from the pose before, default joints, a pose drawn for each place) comes after the command and
is printed apart. So is the compute per window (the sound's network and the rest of the
engine's work on that window), which a live wearable adds on top: by the wall clock (more on a
busy machine) and by the CPU the engine's thread used.

Options that measure what a change would do without changing Servant: `--arrive-alone P` sets
the probability at which one sound window alone names a place arriving (the decision pipeline's
`arrive_sure`; `none`: only two windows in a row, the rule before issue 37's change);
`--confirm-window S` (the Settings' confirm window) changes how far back the pictures count.
Wrong moves are counted too, so that a faster rule's cost shows beside its gain: a taught pose
sent at an untaught place before the switch, and after it a pose neither the place's nor the
one the arm held.

    OMP_NUM_THREADS=1 python bench/arm_latency.py [--places 2] [--draws 4] [--trials 12]
        [--before 30] [--after 40] [--arrive-alone P] [--confirm-window 20] [--json FILE]
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import statistics
import sys
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import add_arrive_sure, shared_data  # noqa: E402
from bench.wearer_day import (  # noqa: E402
    WINDOW_S,
    Data,
    RecordingLink,
    in_background,
)
from servant_core.capture.replay import Clip, PacedAudio  # noqa: E402
from servant_core.capture.source import ManualClock  # noqa: E402
from servant_core.cli import library_noise_silenced  # noqa: E402
from servant_core.engine.core import Engine  # noqa: E402
from servant_core.engine.factories import live_policy, steady  # noqa: E402
from servant_core.events import AcousticPrediction, Decision  # noqa: E402
from servant_core.fusion import elsewhere, pipeline  # noqa: E402
from servant_core.fusion.sequential import FusionConfig  # noqa: E402
from servant_core.library import TEACH_WINDOWS, read_picture  # noqa: E402
from servant_core.recognisers import FRESH_METHODS, UNKNOWN, make_recogniser  # noqa: E402
from servant_core.settings import Settings, default_joints  # noqa: E402

TAUGHT_PICTURES = 6


@dataclass
class Trial:
    target: str
    before: str  # "untaught <scene>" or "taught <scene>"
    offset_s: float  # where in the window cycle the switch fell (0 to 5 s)
    switch_s: float
    first_whole_window_s: float  # the end of the first window wholly of the place, after the switch
    alone_s: float | None  # first window after the switch that names the place on its own
    heard_s: float | None  # first window held steady that names it
    decided_s: float | None  # first decision of it
    moved_s: float | None  # first move command to its pose (None: none within --after)
    settle_s: float  # the arm's joints reaching the pose after the command, at their speeds
    # an untaught place before the switch, and the arm was sent a taught place's pose there
    wrong_before: bool
    # after the switch, the arm was sent a pose neither the target's nor the one it held (the
    # pose it held, sent again while the last window still names the place before, would not
    # reach a real arm standing there: the engine sends nothing then)
    wrong_after: bool
    window_ms: list[tuple[float, float]]  # compute per window: (wall clock, this thread's CPU)


class SwitchCamera:
    """The pictures of the place before until the switch, then the target's."""

    name = "switch camera"

    def __init__(self, clock: ManualClock, switch_s: float, before: list, after: list) -> None:
        self.clock, self.switch_s = clock, switch_s
        self.before, self.after = before, after
        self.shown = 0

    def open(self) -> None:
        pass

    def read(self) -> np.ndarray:
        pictures = self.before if self.clock() < self.switch_s else self.after
        self.shown += 1
        return pictures[self.shown % len(pictures)]

    def close(self) -> None:
        pass


class TimedAudio(PacedAudio):
    """A replay that times the engine's work on each window, by the wall clock and by the CPU
    this thread used (which other work on a busy machine does not inflate): from the block that
    completes a window to the next read (the window judged, fused, the arm asked)."""

    def __init__(self, clips: list[Clip], rate: int, clock: ManualClock) -> None:
        super().__init__(clips, rate, realtime=False, clock=clock)
        self.window = int(round(WINDOW_S * rate))
        self.given = 0
        self.started: tuple[float, float] | None = None
        self.window_ms: list[tuple[float, float]] = []

    def read(self, timeout: float) -> np.ndarray | None:
        if self.started is not None:
            wall, cpu = self.started
            self.window_ms.append(
                ((time.perf_counter() - wall) * 1000, (time.thread_time() - cpu) * 1000)
            )
            self.started = None
        block = super().read(timeout)
        if block is not None:
            before, self.given = self.given, self.given + len(block)
            if self.given // self.window > before // self.window:
                self.started = (time.perf_counter(), time.thread_time())
        return block


class Steadying:
    """The engine's `steady_open`, watched while `watching()`: what each window alone names is
    noted with the engine's time (`alone`), from its probabilities and the recogniser's own
    answer for it (unknown though its probabilities name a place: far from every taught
    window). The engine's decision is left as `steady_open` makes it."""

    def __init__(self, recogniser: Any) -> None:
        self.alone: list[tuple[float, str | None]] = []
        self.answered = UNKNOWN  # the recogniser's answer for the window being judged
        answers = recogniser.answers

        def noted(X: np.ndarray) -> Any:
            found = answers(X)
            self.answered = str(found[0][-1])
            return found

        recogniser.answers = noted

    def steady_open(
        self,
        clock: ManualClock,
        window: dict[str, float],
        previous: dict[str, float],
        far: bool,
        named_before: str | None = None,
        **sure: Any,
    ) -> tuple[str | None, dict[str, float]]:
        far_alone = self.answered == UNKNOWN and sum(window.values()) > 0.5
        alone, _ = elsewhere.steady_open(window, window, far_alone, None)
        self.alone.append((clock(), alone))
        return elsewhere.steady_open(window, previous, far, named_before, **sure)

    @contextlib.contextmanager
    def watching(self, clock: ManualClock) -> Iterator[None]:
        """The engine's decisions, through its `DecisionPipeline`, hear this `steady_open`."""
        if getattr(pipeline, "steady_open", None) is not elsewhere.steady_open:
            raise SystemExit("the decision pipeline no longer calls steady_open: update this bench")
        self.alone = []
        pipeline.steady_open = functools.partial(self.steady_open, clock)  # type: ignore[assignment]
        try:
            yield
        finally:
            pipeline.steady_open = elsewhere.steady_open


def settle_s(before: dict[str, float], pose: dict[str, float]) -> float:
    """Seconds the default joints take from `before` to `pose` at their top speeds."""
    return max(abs(pose[j.name] - before[j.name]) / j.max_speed_deg_s for j in default_joints())


def poses_for(places: list[str], rng: np.random.Generator) -> dict[str, dict[str, float]]:
    """A pose for each place within the default joints' limits, whole degrees."""
    return {
        place: {
            j.name: float(round(rng.uniform(j.min_angle, j.max_angle))) for j in default_joints()
        }
        for place in places
    }


def stretch(windows: np.ndarray, seconds: float, rng: np.random.Generator, rate: int) -> np.ndarray:
    """`seconds` of a recording's audio (its `windows` run together) from a random start."""
    audio = windows.reshape(-1)
    need = int(round(seconds * rate))
    if len(audio) < need:  # a short recording: played again from its start
        audio = np.tile(audio, need // len(audio) + 1)
    start = int(rng.integers(0, len(audio) - need + 1))
    return audio[start : start + need]


class Draw:
    """One library taught: the places, their recognisers, what is left to walk through."""

    def __init__(self, data: Data, places: int, rng: np.random.Generator, args: Any) -> None:
        self.rate = data.rate
        self.places = sorted(rng.choice(data.both, places, replace=False).tolist())
        self.poses = poses_for(self.places, rng)
        self.confirm = args.confirm_window
        self.arrive_sure = args.arrive_alone
        X, y, pictures, labels = [], [], [], []
        self.later: dict[str, np.ndarray] = {}
        self.later_pictures: dict[str, list[np.ndarray]] = {}
        for place in self.places:
            own = [
                r
                for r in data.recordings[place]
                if not in_background(r[0]) and len(r[1]) > TEACH_WINDOWS + 1
            ]
            _, windows = own[int(rng.integers(len(own)))]
            X.append(windows[:TEACH_WINDOWS])
            y += [place] * len(windows[:TEACH_WINDOWS])
            self.later[place] = windows[TEACH_WINDOWS:]
            paths = [data.pictures[place][i] for i in rng.permutation(len(data.pictures[place]))]
            pictures += [read_picture(p) for p in paths[:TAUGHT_PICTURES]]
            labels += [place] * TAUGHT_PICTURES
            self.later_pictures[place] = [read_picture(p) for p in paths[TAUGHT_PICTURES:][:8]]
        self.audio = make_recogniser("audio", FRESH_METHODS["audio"])
        self.audio.fit(self.audio.featurize(np.concatenate(X)), y)
        self.steadying = Steadying(self.audio)
        self.visual = make_recogniser("image", FRESH_METHODS["image"])
        self.visual.fit(self.visual.featurize(pictures), labels)
        self.untaught = [
            (scene, windows)
            for scene, recordings in data.recordings.items()
            if scene not in self.places
            for name, windows in recordings
            if not in_background(name)
        ]
        picture_scenes = [s for s in data.pictures if s not in self.places]
        self.untaught_pictures = {
            s: [read_picture(p) for p in data.pictures[s][:8]] for s in picture_scenes
        }

    def trial(
        self, target: str, untaught: bool, args: argparse.Namespace, rng: np.random.Generator
    ) -> Trial:
        offset = float(rng.uniform(0.0, WINDOW_S))
        switch = WINDOW_S * round(args.before / WINDOW_S) + offset
        if untaught:
            scene, windows = self.untaught[int(rng.integers(len(self.untaught)))]
            looks = scene if scene in self.untaught_pictures else None
            looks = looks or list(self.untaught_pictures)[rng.integers(len(self.untaught_pictures))]
            before_pictures = self.untaught_pictures[looks]
            before = f"untaught {scene}"
        else:
            scene = str(rng.choice([p for p in self.places if p != target]))
            windows = self.later[scene]
            before_pictures = self.later_pictures[scene]
            before = f"taught {scene}"
        clips = [
            Clip(scene, stretch(windows, switch, rng, self.rate)),
            Clip(target, stretch(self.later[target], args.after, rng, self.rate)),
        ]
        clock = ManualClock()
        source = TimedAudio(clips, self.rate, clock)
        camera = SwitchCamera(clock, switch, before_pictures, self.later_pictures[target])
        engine = Engine(
            audio=source,
            camera=camera,
            acoustic=self.audio,
            visual=self.visual,
            fusion=live_policy("parallel", FusionConfig(confirm_window_s=self.confirm)),
            clock=clock,
            confidence_threshold=Settings().confidence_threshold,
            smoother=steady(),
        )
        engine.decisions.arrive_sure = self.arrive_sure
        link = RecordingLink(clock)
        engine.set_arm(link)
        engine.set_action_learner(lambda scene, scores, confidence: {"place": scene})
        heard: list[tuple[float, str | None]] = []
        decided: list[tuple[float, str | None]] = []

        def listen(event: Any) -> None:
            if isinstance(event, AcousticPrediction):
                heard.append((event.t, event.scene))
            elif isinstance(event, Decision):
                decided.append((event.t, event.scene))

        engine.subscribe(listen)
        with self.steadying.watching(clock), library_noise_silenced():
            engine.run_until(switch + args.after + 1.0)
        engine.stop()

        def first(events: list[tuple[float, Any]]) -> float | None:
            return next((t - switch for t, what in events if t > switch and what == target), None)

        moved = first(link.moves)
        # where the arm stood at the switch: the last pose sent before it, else home
        last = [place for t, place in link.moves if t <= switch][-1:]
        home = {j.name: j.home_angle for j in default_joints()}
        return Trial(
            target=target,
            before=before,
            offset_s=offset,
            switch_s=switch,
            first_whole_window_s=2 * WINDOW_S - offset,
            alone_s=first(self.steadying.alone),
            heard_s=first(heard),
            decided_s=first(decided),
            moved_s=moved,
            settle_s=settle_s(self.poses[last[0]] if last else home, self.poses[target]),
            wrong_before=untaught and any(t <= switch for t, _ in link.moves),
            wrong_after=any(t > switch and p not in (target, *last) for t, p in link.moves),
            window_ms=source.window_ms,
        )


def quartiles(values: list[float]) -> tuple[float, float, float]:
    q1, q2, q3 = statistics.quantiles(values, n=4, method="inclusive")
    return q1, q2, q3


def report(trials: list[Trial], after: float) -> dict[str, Any]:
    moved = [t.moved_s for t in trials if t.moved_s is not None]
    # a trial with no move within --after waited longer than any that moved: counted as such
    waits = sorted([*moved, *[float("inf")] * (len(trials) - len(moved))])
    q1, median, q3 = quartiles(waits) if len(waits) >= 2 else (waits[0],) * 3
    within = sum(w <= 10.0 for w in waits) / len(waits)
    print(
        f"switch → the arm's move command ({len(trials)} trials, engine time): median "
        f"{median:.1f} s, quartiles {q1:.1f}–{q3:.1f} s; within 10 s in {within:.2f}; "
        f"no move within {after:g} s in {len(trials) - len(moved)}"
    )
    settle = [t.settle_s for t in trials]
    print(
        f"  then the arm reaches the pose (default joints' speeds) after a median "
        f"{statistics.median(settle):.1f} s more (quartiles {quartiles(settle)[0]:.1f}–"
        f"{quartiles(settle)[2]:.1f} s)"
    )
    steps = {
        "the first whole window of the place ends": [t.first_whole_window_s for t in trials],
        "a window alone names it": [t.alone_s for t in trials],
        "the sound names it (held steady)": [t.heard_s for t in trials],
        "the fusion decides it": [t.decided_s for t in trials],
        "the arm is sent its pose": [t.moved_s for t in trials],
    }
    print("  where the time goes (median seconds after the switch; n: trials where it came):")
    for what, values in steps.items():
        came = [v for v in values if v is not None]
        figure = f"{statistics.median(came):5.1f} s" if came else "    –  "
        print(f"    {what:<42} {figure}  (n {len(came)})")
    for kind in ("untaught", "taught"):
        some = [t for t in trials if t.before.startswith(kind)]
        waits_kind = [t.moved_s if t.moved_s is not None else float("inf") for t in some]
        if waits_kind:
            print(
                f"  after {'an untaught' if kind == 'untaught' else 'another taught'} place: "
                f"median {statistics.median(waits_kind):.1f} s over {len(some)} trials, within "
                f"10 s in {sum(w <= 10 for w in waits_kind) / len(waits_kind):.2f}"
            )
    early = [t for t in trials if t.offset_s < WINDOW_S / 2]
    late = [t for t in trials if t.offset_s >= WINDOW_S / 2]
    for name, some in (("first half", early), ("second half", late)):
        if some:
            waits_half = [t.moved_s if t.moved_s is not None else float("inf") for t in some]
            print(
                f"  switch in the window's {name}: median {statistics.median(waits_half):.1f} s "
                f"({len(some)} trials)"
            )
    untaught = [t for t in trials if t.before.startswith("untaught")]
    stay = statistics.median([t.switch_s for t in trials])
    print(
        f"  the arm sent a wrong pose: in {sum(t.wrong_before for t in untaught)} of "
        f"{len(untaught)} stays of about {stay:.0f} s at an untaught place (before the switch), "
        f"and after the switch in {sum(t.wrong_after for t in trials)} of {len(trials)} trials"
    )
    wall = [ms for t in trials for ms, _ in t.window_ms]
    cpu = [ms for t in trials for _, ms in t.window_ms]
    print(
        f"  compute per window (the sound's network, fusion, the arm; a picture when one is "
        f"due), over {len(wall)} windows: wall clock median {statistics.median(wall):.0f} ms "
        f"(90th percentile {np.percentile(wall, 90):.0f} ms), CPU median "
        f"{statistics.median(cpu):.0f} ms (90th percentile {np.percentile(cpu, 90):.0f} ms)"
    )
    return {
        "median_s": median,
        "quartiles_s": [q1, q3],
        "within_10s": within,
        "no_move": len(trials) - len(moved),
        "settle_median_s": statistics.median(settle),
        "window_ms_median": {"wall": statistics.median(wall), "cpu": statistics.median(cpu)},
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=shared_data())
    parser.add_argument("--places", type=int, default=2, help="places taught (default: 2)")
    parser.add_argument("--draws", type=int, default=4, help="libraries taught (default: 4)")
    parser.add_argument("--trials", type=int, default=12, help="switches a draw (default: 12)")
    parser.add_argument(
        "--before", type=float, default=30.0, help="seconds somewhere else first (default: 30)"
    )
    parser.add_argument(
        "--after", type=float, default=40.0, help="seconds at the place after (default: 40)"
    )
    add_arrive_sure(parser)
    parser.add_argument(
        "--confirm-window",
        type=float,
        default=FusionConfig().confirm_window_s,
        help="the fusion's confirm window in seconds (default: the Settings', %(default)g)",
    )
    parser.add_argument("--seed", type=int, default=0, help="the draws' seed (default: 0)")
    parser.add_argument("--json", type=Path, help="also write the trials here")
    args = parser.parse_args()
    if not (args.data / "audio" / "dev").is_dir():
        print(f"no real data at {args.data}; nothing to measure")
        return 0
    rate = make_recogniser("audio", FRESH_METHODS["audio"]).rate
    started = time.time()
    windows = TEACH_WINDOWS + int(np.ceil(max(args.before, args.after) / WINDOW_S)) + 12
    with library_noise_silenced():
        data = Data(args.data, rate, windows)
    if len(data.both) < args.places:
        print(f"only {len(data.both)} scenes have both recordings and pictures; nothing to measure")
        return 0
    print(
        f"{args.places} places taught a draw ({TEACH_WINDOWS} windows, {TAUGHT_PICTURES} pictures "
        f"each, {FRESH_METHODS['audio']} and {FRESH_METHODS['image']}), {args.draws} draws of "
        f"{args.trials} switches after about {args.before:g} s elsewhere; confirm window "
        f"{args.confirm_window:g} s"
        + (
            "; a place named on two windows in a row only"
            if args.arrive_alone is None
            else f"; a place named on one window that gives it {args.arrive_alone:g} or more"
        )
    )
    trials: list[Trial] = []
    for draw_index in range(args.draws):
        rng = np.random.default_rng([args.seed, args.places, draw_index])
        with library_noise_silenced():
            draw = Draw(data, args.places, rng, args)
        for i in range(args.trials):
            target = draw.places[i % len(draw.places)]
            untaught = (i // len(draw.places)) % 2 == 0  # each place after both kinds of stay
            trials.append(draw.trial(target, untaught, args, rng))
        done = trials[-args.trials :]
        print(
            f"  draw {draw_index}: {', '.join(draw.places)}; moves after "
            + " ".join("–" if t.moved_s is None else f"{t.moved_s:.1f}" for t in done)
            + f" s ({time.time() - started:.0f} s so far)",
            flush=True,
        )
    figures = report(trials, args.after)
    if args.json:
        args.json.write_text(
            json.dumps({"figures": figures, "trials": [asdict(t) for t in trials]}, indent=2)
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
