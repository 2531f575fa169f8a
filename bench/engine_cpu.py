"""CPU use of the running engine, and the latency from the end of a window to its events.

The input is microphone-equivalent: a real recording replayed at real speed (44.1 kHz, 20 ms
blocks, as a PortAudio stream delivers them), pictures of the scene being heard from the real
photographs, the paper's recognisers trained on the real data at 44.1 kHz, spectrum frames at 30
per second. No UI. Two runs:

1. the paper's fusion (30 s window, 3 pictures 2 s apart): CPU use, and latency from a window's
   end to its AcousticPrediction;
2. fusion confirming on 1 picture: the decision then follows in the same turn as the window,
   so this measures the whole chain window → features → K-Means → picture → palette → decision.

Targets (issue 3): ≤ 15 % of one core; ≤ 50 ms median from window end to decision.

    python bench/engine_cpu.py [--seconds 30]

Without ../shared/data (or $SERVANT_SHARED_DATA) it runs on the demo's synthesised scenes (16 kHz).
"""

from __future__ import annotations

import argparse
import resource
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from common import shared_data  # noqa: E402

from servant_core.audio import read_audio  # noqa: E402
from servant_core.capture.replay import Clip, PacedAudio, PictureReplay  # noqa: E402
from servant_core.engine import Engine  # noqa: E402
from servant_core.events import AcousticPrediction, Decision  # noqa: E402
from servant_core.fusion import FusionConfig, SequentialFusion  # noqa: E402
from servant_core.library import SceneLibrary, read_pictures  # noqa: E402
from servant_core.recognisers.paper import PaperAcousticRecogniser, PaperVisualRecogniser  # noqa: E402

RATE = 44100
SCENES = ("cafe", "street", "station")
TRAIN_WINDOWS = 8  # per scene, from the start of each scene's first recording
PICTURES = 20  # per scene, for training; the replay shows the others


def demo_setup(rate: int = RATE):
    """The demo's synthesised scenes at `rate`: sound and pictures that the paper's recognisers
    do tell apart, so that decisions happen and the whole chain can be timed."""
    from servant_core.demo.scenes import SCENES as DEMO_SCENES
    from servant_core.demo.scenes import synth_picture, synth_window, train_demo_recognisers

    _, visual = train_demo_recognisers(0)
    windows = [
        synth_window(s, np.random.default_rng([1, i, k]), rate=rate)
        for i, s in enumerate(DEMO_SCENES)
        for k in range(6)
    ]
    acoustic = PaperAcousticRecogniser(rate=rate, n_init=3)
    acoustic.fit(acoustic.featurize(np.stack(windows)), [s for s in DEMO_SCENES for _ in range(6)])
    # 40 s a scene: a change of scene holds the paper's policy up for 30 s, which is not timed here.
    clips = [
        Clip(s, synth_window(s, np.random.default_rng([2, i]), 40.0, rate))
        for i, s in enumerate(DEMO_SCENES)
    ]

    class SceneCamera:
        """Shows a synthesised picture of the scene being heard."""

        name = "synthesised camera"

        def __init__(self) -> None:
            self.count = 0
            self.source: PacedAudio | None = None
            # Drawn beforehand: a camera's frame is captured by its hardware, not by the engine.
            self.frames = {
                s: [synth_picture(s, np.random.default_rng([3, i, k])) for k in range(8)]
                for i, s in enumerate(DEMO_SCENES)
            }

        def open(self) -> None: ...
        def close(self) -> None: ...

        def read(self):
            self.count += 1
            scene = (self.source.current_label if self.source else None) or DEMO_SCENES[0]
            return self.frames[scene][self.count % 8]

    return acoustic, visual, clips, SceneCamera(), rate


def real_setup(data: Path):
    """(acoustic, visual, test clip, its scene labels per sample segment, replay pictures)."""
    audio_lib = SceneLibrary.scan(data / "audio" / "dev").restricted(SCENES)
    image_lib = SceneLibrary.scan(data / "images" / "dev").restricted(SCENES)
    acoustic = PaperAcousticRecogniser(rate=RATE, n_init=3)
    windows, labels, clips = [], [], []
    size = 5 * RATE
    for scene in SCENES:
        recording = next(r for r in audio_lib.recordings if r.scene == scene)
        signal = read_audio(recording.path, RATE)
        train = signal[: TRAIN_WINDOWS * size].reshape(TRAIN_WINDOWS, size)
        windows.append(train)
        labels += [scene] * TRAIN_WINDOWS
        clips.append(Clip(scene, signal[TRAIN_WINDOWS * size : (TRAIN_WINDOWS + 4) * size]))
    acoustic.fit(acoustic.featurize(np.concatenate(windows)), labels)
    train_pictures = [
        p for s in SCENES for p in [q for q in image_lib.pictures if q.scene == s][:PICTURES]
    ]
    test_pictures = [p for p in image_lib.pictures if p not in train_pictures]
    images, kept = read_pictures(train_pictures)
    visual = PaperVisualRecogniser(n_init=3)
    visual.fit(visual.featurize(images), [p.scene for p in kept])
    return acoustic, visual, clips, test_pictures, RATE


class Stamped:
    """Wraps the audio source to note the wall time at which each window's last sample arrived."""

    def __init__(self, source: PacedAudio, window: int) -> None:
        self.source = source
        self.window = window
        self.samples = 0
        self.window_ends: list[float] = []
        self.turn = 0

    def __getattr__(self, name):
        return getattr(self.source, name)

    def read(self, timeout):
        block = self.source.read(timeout)
        self.turn += 1
        if block is not None:
            before = self.samples
            self.samples += len(block)
            if self.samples // self.window > before // self.window:
                self.window_ends.append(time.perf_counter())
        return block


def run(setup, fusion, seconds: float) -> dict:
    acoustic, visual, clips, pictures, rate = setup
    source = PacedAudio(list(clips) * 10, rate, realtime=True, name="replay at real speed")
    stamped = Stamped(source, 5 * rate)
    if isinstance(pictures, list):
        camera = PictureReplay(pictures, scene_of=lambda: source.current_label)
    else:
        camera, camera.source = pictures, source
    engine = Engine(audio=stamped, camera=camera, acoustic=acoustic, visual=visual, fusion=fusion)
    heard: list[tuple[int, float]] = []  # (window index, perf time)
    decided: list[tuple[int, int, float]] = []  # (turn, windows so far, perf time)
    turn_of_window: list[int] = []

    def listen(event) -> None:
        now = time.perf_counter()
        if isinstance(event, AcousticPrediction):
            heard.append((len(heard), now))
            turn_of_window.append(stamped.turn)
        elif isinstance(event, Decision):
            decided.append((stamped.turn, len(heard), now))

    engine.subscribe(listen)
    usage0 = resource.getrusage(resource.RUSAGE_SELF)
    wall0 = time.perf_counter()
    engine.start()
    time.sleep(seconds)
    usage1 = resource.getrusage(resource.RUSAGE_SELF)
    wall1 = time.perf_counter()
    engine.stop()
    cpu = (usage1.ru_utime - usage0.ru_utime) + (usage1.ru_stime - usage0.ru_stime)
    to_prediction = [
        (t - stamped.window_ends[k]) * 1000 for k, t in heard if k < len(stamped.window_ends)
    ]
    to_decision = [
        (t - stamped.window_ends[n - 1]) * 1000
        for turn, n, t in decided
        if n > 0 and turn == turn_of_window[n - 1]  # decided in the turn that ended window n
    ]
    return {
        "cpu_percent": 100 * cpu / (wall1 - wall0),
        "windows": len(heard),
        "to_prediction_ms": to_prediction,
        "to_decision_ms": to_decision,
        "decisions": len(decided),
        "overflows": getattr(source, "overflows", 0),
    }


def breakdown(setup) -> str:
    """Median single-thread cost of each step for one window and one picture (this process)."""
    from servant_core.engine import _predict
    from servant_core.features.palette import dominant_colours

    acoustic, visual, clips, camera, rate = setup
    window = clips[0].samples[None, : 5 * rate]
    frame = camera.read()
    X = acoustic.featurize(window)
    Xv = visual.featurize([frame])
    steps = {
        "featurize": lambda: acoustic.featurize(window),
        "predict+confidence+proba": lambda: _predict(acoustic, X),
        "of which 1 distance": lambda: acoustic.distances(X),
        "picture: featurize+predict": lambda: _predict(visual, visual.featurize([frame])),
        "palette": lambda: dominant_colours(frame),
    }
    del Xv
    parts = []
    for name, step in steps.items():
        times = []
        for _ in range(7):
            start = time.perf_counter()
            step()
            times.append((time.perf_counter() - start) * 1000)
        parts.append(f"{name} {np.median(times):.1f}")
    return ", ".join(parts) + " (ms)"


def summary(values: list[float]) -> str:
    if not values:
        return "n/a"
    v = np.array(values)
    return (
        f"median {np.median(v):.1f} ms, p90 {np.percentile(v, 90):.1f} ms, "
        f"max {v.max():.1f} ms (n={len(v)})"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0)
    args = parser.parse_args()
    data = shared_data()
    threads_before = threading.active_count()
    print(f"synthesising the demo scenes at {RATE} Hz and training the paper's recognisers ...")
    demo_scenes = demo_setup()
    demo = run(demo_scenes, SequentialFusion(FusionConfig(pictures_needed=1)), args.seconds)
    real = None
    if (data / "audio" / "dev").is_dir():
        print(f"training the paper's recognisers at {RATE} Hz on {', '.join(SCENES)} ...")
        real = run(real_setup(data), SequentialFusion(), args.seconds)
    out = [f"\nengine over {args.seconds:g} s of real-speed replay at {RATE} Hz, no UI"]
    if real is not None:
        out += [
            f"  real recordings, paper's fusion: CPU {real['cpu_percent']:.1f} % of one core"
            " (target <= 15 %)",
            f"    window end -> acoustic event: {summary(real['to_prediction_ms'])}",
        ]
    out += [
        f"  demo scenes, 1-picture fusion:   CPU {demo['cpu_percent']:.1f} % of one core",
        f"    window end -> acoustic event: {summary(demo['to_prediction_ms'])}",
        f"    window end -> decision event: {summary(demo['to_decision_ms'])}"
        " (target median <= 50 ms)",
        f"  per-step cost, single thread: {breakdown(demo_scenes)}",
        f"  threads left behind: {threading.active_count() - threads_before}",
    ]
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
