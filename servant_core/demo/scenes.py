"""The demo's scenes and its walk: a coffee shop, a basketball gym and a street, all synthesised.

Deterministic by seed: training from `default_rng([seed, TRAIN, ...])`, the walk from
`default_rng([seed, WALK, ...])`, never sharing a sound or a picture. Audio runs at `DEMO_RATE`
(16 kHz), the paper's method trained at that rate. The walk (`WALK`, 95 s, repeated): the coffee
shop, the gym, a street heard while the camera still shows the café (ending in "No scene detected"
after 30 s), then the street; the camera turns one window (5 s) after the sound changes.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from servant_core.audio import DEFAULT_WINDOW_SECONDS, write_wav
from servant_core.capture.replay import DEFAULT_BLOCK_SECONDS, Clip, PacedAudio
from servant_core.demo.audio_synth import DEMO_RATE, SCENE_SOUNDS
from servant_core.demo.picture_synth import SCENE_PICTURES
from servant_core.recognisers import FRESH_METHODS, make_recogniser
from servant_core.recognisers.paper import PaperAcousticRecogniser, PaperVisualRecogniser
from servant_core.storage import atomic_write_bytes
from servant_core.threads import results_in_order

SCENES = ("coffee", "gym", "street")
TRAIN, WALK_STREAM = 1, 2  # the first seed word after the user's seed: which stream of randomness


@dataclass(frozen=True)
class Segment:
    sound: str  # the scene heard
    sight: str  # the scene the camera shows
    seconds: float
    note: str


WALK = (
    Segment("coffee", "coffee", 20.0, "in the coffee shop"),
    Segment("gym", "gym", 20.0, "on the basketball court"),
    Segment(
        "street", "coffee", 35.0, "outside, still looking into the café: sound and sight disagree"
    ),
    Segment("street", "street", 20.0, "walking down the street"),
)
CAMERA_LAG_S = DEFAULT_WINDOW_SECONDS
# Each place's typical loudness (RMS, dB re full scale). The paper's raw-FFT K-Means compares
# amplitudes: a level wandering by 10 dB from window to window splits one place into two clusters,
# and a much louder place spreads wider (noise spectra fluctuate in proportion to their level).
SCENE_LEVEL_DB = {"coffee": -32.0, "gym": -30.0, "street": -29.0}


def walk_length(walk: tuple[Segment, ...] = WALK) -> float:
    return sum(s.seconds for s in walk)


def segment_at(t: float, walk: tuple[Segment, ...] = WALK) -> Segment:
    """The segment of the (endlessly repeated) walk at time `t` seconds; before 0, the first."""
    t = max(0.0, t) % walk_length(walk)
    for segment in walk:
        if t < segment.seconds:
            return segment
        t -= segment.seconds
    return walk[-1]


def synth_window(
    scene: str,
    rng: np.random.Generator,
    seconds: float = DEFAULT_WINDOW_SECONDS,
    rate: int = DEMO_RATE,
) -> np.ndarray:
    """A window of the scene's sound at its typical loudness (within ±1.5 dB)."""
    x = SCENE_SOUNDS[scene](rng, seconds, rate)
    level_db = SCENE_LEVEL_DB[scene] + rng.uniform(-1.5, 1.5)
    rms = float(np.sqrt(np.mean(x.astype(np.float64) ** 2))) or 1.0
    return (x * (10 ** (level_db / 20) / rms)).astype(np.float32)


def synth_picture(scene: str, rng: np.random.Generator) -> np.ndarray:
    return SCENE_PICTURES[scene](rng)


TrainingSet = tuple[np.ndarray, list[str], list[np.ndarray], list[str]]


def training_set(
    seed: int = 0,
    windows_per_scene: int = 6,
    pictures_per_scene: int = 6,
    on_progress: Callable[[int, int], None] | None = None,
) -> TrainingSet:
    """(windows (n, samples) at DEMO_RATE, their scenes, pictures, their scenes);
    `on_progress(done, total)` after each scene's windows and pictures."""
    jobs = [
        functools.partial(make, scene, np.random.default_rng([seed, TRAIN, s, kind, i]))
        for s, scene in enumerate(SCENES)
        for kind, make, count in (
            (0, synth_window, windows_per_scene),
            (1, synth_picture, pictures_per_scene),
        )
        for i in range(count)
    ]
    made = results_in_order(jobs)  # each seeded on its own: the same whatever the threads
    windows, window_scenes, pictures, picture_scenes = [], [], [], []
    for s, scene in enumerate(SCENES):
        windows += [next(made) for _ in range(windows_per_scene)]
        window_scenes += [scene] * windows_per_scene
        pictures += [next(made) for _ in range(pictures_per_scene)]
        picture_scenes += [scene] * pictures_per_scene
        if on_progress is not None:
            on_progress(s + 1, len(SCENES))
    return np.stack(windows), window_scenes, pictures, picture_scenes


def demo_recognisers(seed: int = 0, *, paper: bool = True) -> tuple[Any, Any]:
    """Unfitted recognisers for the demo: the paper's (`paper`), or the methods beyond it."""
    if paper:
        return (
            PaperAcousticRecogniser(rate=DEMO_RATE, random_state=seed),
            PaperVisualRecogniser(random_state=seed),
        )
    return (
        make_recogniser("audio", FRESH_METHODS["audio"], rate=DEMO_RATE, random_state=seed),
        make_recogniser("image", FRESH_METHODS["image"], random_state=seed),
    )


# A recogniser's fit takes about as long as synthesising two scenes (bench/progress_estimates.py)
FIT_STEPS = 2
# The demo's training in steps: each scene synthesised, then the two fits.
TRAINING_STEPS = len(SCENES) + 2 * FIT_STEPS


def train_demo_recognisers(
    seed: int = 0,
    windows_per_scene: int = 6,
    pictures_per_scene: int = 6,
    *,
    paper: bool = True,
    on_progress: Callable[[int, int], None] | None = None,
    training: TrainingSet | None = None,
) -> tuple[Any, Any]:
    """The demo's two recognisers (see `demo_recognisers`), fitted on freshly synthesised scenes
    (a second or two), or on `training` (`training_set`'s, made already); `on_progress(done,
    total)` after each scene synthesised and each fit, a fit counting as `FIT_STEPS` scenes
    (about its share of the time: the bar's estimate assumes a steady pace)."""
    total = TRAINING_STEPS

    def report(done: int, _total: int = total) -> None:
        if on_progress is not None:
            on_progress(done, total)

    if training is None:
        training = training_set(seed, windows_per_scene, pictures_per_scene, report)
    else:
        report(len(SCENES))
    windows, window_scenes, pictures, picture_scenes = training
    acoustic, visual = demo_recognisers(seed, paper=paper)
    acoustic.fit(acoustic.featurize(windows), window_scenes)
    report(len(SCENES) + FIT_STEPS)
    visual.fit(visual.featurize(pictures), picture_scenes)
    report(total)
    return acoustic, visual


def write_demo_library(
    root: str | Path, seed: int = 0, training: TrainingSet | None = None
) -> Path:
    """The demo's training scenes (`training`, else made from `seed`) as a scene library under
    `root` (WAV windows and PNG pictures, as teach mode writes them), so that the library screen
    shows them and a retrain learns them again."""
    root = Path(root)
    windows, window_scenes, pictures, picture_scenes = training or training_set(seed)
    for i, (window, scene) in enumerate(zip(windows, window_scenes, strict=True)):
        write_wav(root / scene / f"demo-{i:02d}.wav", window, DEMO_RATE)
    for i, (picture, scene) in enumerate(zip(pictures, picture_scenes, strict=True)):
        ok, png = cv2.imencode(".png", picture)
        if ok:
            atomic_write_bytes(root / scene / f"demo-{i:02d}.png", png.tobytes())
    return root


def walk_clips(seed: int = 0, walk: tuple[Segment, ...] = WALK) -> Iterator[Clip]:
    """The walk's sound, window by window, forever; window k is seeded by (seed, k)."""
    for k in itertools.count():
        scene = segment_at(k * DEFAULT_WINDOW_SECONDS, walk).sound
        rng = np.random.default_rng([seed, WALK_STREAM, 0, k])
        yield Clip(scene, synth_window(scene, rng))


# As fast as possible the walk goes on in blocks of 0.1 s, not a microphone's 20 ms: each block is a
# round of the engine's loop (the camera's, the sensors' and the fusion's turns), and the demo's
# events are still on a 0.1 s grid (a picture is of the walk's time to 0.1 s; windows are 5 s).
FAST_BLOCK_SECONDS = 0.1


def demo_audio(seed: int = 0, *, realtime: bool = True, clock=None) -> PacedAudio:
    """The walk's sound as an audio source (at real speed, or as fast as possible on `clock`)."""
    return PacedAudio(
        walk_clips(seed),
        DEMO_RATE,
        realtime=realtime,
        clock=clock,
        block_seconds=DEFAULT_BLOCK_SECONDS if realtime else FAST_BLOCK_SECONDS,
        name="demo sound",
    )


class DemoCamera:
    """A frame source showing the walk's place, `CAMERA_LAG_S` behind its sound.

    The walk begins when the camera is first opened, with the sound (the engine opens both when it
    starts), not when its clock (`clock()`, the engine's) began. A picture depends only on the seed
    and the walk's time (to 0.1 s), so a run on a `ManualClock` shows the same pictures every time.
    """

    def __init__(
        self, clock: Callable[[], float], seed: int = 0, walk: tuple[Segment, ...] = WALK
    ) -> None:
        self.name = "demo camera"
        self.clock = clock
        self.seed = seed
        self.walk = walk
        self.began_at: float | None = None  # the clock's time when the walk began

    def open(self) -> None:
        if self.began_at is None:  # a reopened camera goes on with the same walk
            self.began_at = self.clock()

    def read(self) -> np.ndarray:
        if self.began_at is None:
            self.began_at = self.clock()
        t = self.clock() - self.began_at
        scene = (
            segment_at(t - CAMERA_LAG_S, self.walk).sight
            if t >= CAMERA_LAG_S
            else self.walk[0].sight
        )
        rng = np.random.default_rng([self.seed, WALK_STREAM, 1, int(round(t * 10))])
        return synth_picture(scene, rng)

    def close(self) -> None:
        pass
