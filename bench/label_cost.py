"""What labelling a picture costs, the model's part and the whole path (issue 41 item 6 saw
20-125 s a label with the default fisher-bovw model, slower with each).

1. The model: the engine's `folded_in` (featurize, copy, `fold_in`) of one picture after another
   into a two-place `fisher-bovw` model taught six pictures a place, in CPU seconds of this
   process, with the regularisation the fit chose (`C_`) and, for comparison, the C chosen before
   issue 38 (0.003, flat probabilities); and the model file's save.
2. The whole path below the app's "What is this place?": `Engine.label_unknown` (the place's
   name checked, the picture written into the library, folded in, the model file saved), one
   label after another, on a library as teach mode makes it (three places, six 5 s recordings
   and six 640x480 pictures each, retrained: birdnet and fisher-bovw), with the model file the
   app saves to. Wall and CPU seconds of the labelling thread (`time.thread_time`: what the
   machine's other work does not add), and where the wall time went: the write, the fold-in,
   the save. Once with the engine idle, once with it running (its sense thread hearing a
   taught place's sound and seeing pictures, as in the app).
3. With `--app`: the same, answered in the terminal app's dialog (Textual's test pilot, the
   engine running): from Enter to the log's "labelled the unknown place".

    OMP_NUM_THREADS=1 python bench/label_cost.py [--labels 10] [--seed 0] [--app]
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import copy
import shutil
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402
import soundfile as sf  # noqa: E402

from bench.common import shared_data  # noqa: E402
from servant_core.audio import resample, write_wav  # noqa: E402
from servant_core.capture.replay import PictureReplay, replay_recordings  # noqa: E402
from servant_core.engine import Engine, learning  # noqa: E402
from servant_core.engine.learning import Kept, folded_in, save_models  # noqa: E402
from servant_core.library import Picture, Recording, read_picture  # noqa: E402
from servant_core.modelfile import load_model  # noqa: E402
from servant_core.recognisers import make_recogniser  # noqa: E402

SCENES = ("cafe", "street", "office")  # two taught, the third labelled as a new place
TAUGHT = ("cafe", "street", "office")  # the teach-mode library's places
NEW_PLACE = "library"  # pictures of a place never taught, labelled in turn with the taught ones
RATE = 48000  # a microphone's
FRAME = (640, 480)  # a webcam's


def cpu(action):
    start = time.process_time()
    result = action()
    return result, time.process_time() - start


def model_part(root: Path, labels: int, rng: np.random.Generator) -> None:
    paths = {s: sorted((root / s).glob("*.jpg")) for s in SCENES}
    chosen = {s: [paths[s][i] for i in rng.permutation(len(paths[s]))] for s in SCENES}
    taught = [read_picture(p) for s in SCENES[:2] for p in chosen[s][:6]]
    scenes = [s for s in SCENES[:2] for _ in range(6)]
    model = make_recogniser("image", "fisher-bovw")
    _, fit_s = cpu(lambda: model.fit(model.featurize(taught), scenes))
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
        for i in range(labels):
            scene = SCENES[i % 3]
            kept = Kept("image", read_picture(chosen[scene][6 + i]))
            current, seconds = cpu(lambda c=current, k=kept, s=scene: folded_in(c, k, s))
            times.append(seconds)
        print(
            f"labels one after another ({name}): "
            + ", ".join(f"{t:.2f}" for t in times)
            + f" CPU s (median {np.median(times):.2f})"
        )


def teach_mode_library(shared: Path, root: Path) -> None:
    """Three places as teach mode leaves them: six presses of Record 5 s (one real recording
    cut in six) and six pictures from the camera (real photographs at a webcam's size)."""
    for scene in TAUGHT:
        folder = root / scene
        folder.mkdir(parents=True)
        source = sorted((shared / "audio" / "dev" / scene).iterdir())[0]
        sound, rate = sf.read(source, dtype="float32", frames=45 * 48000, always_2d=True)
        sound = resample(sound.mean(axis=1), rate, RATE)
        for press in range(6):
            window = sound[press * 5 * RATE : (press + 1) * 5 * RATE]
            write_wav(folder / f"20260101-12000{press}.wav", window, RATE)
        for i, path in enumerate(sorted((shared / "images" / "dev" / scene).glob("*.jpg"))[:6]):
            cv2.imwrite(str(folder / f"20260101-1201{i:02d}.png"), frame_of(path))


def frame_of(path: Path) -> np.ndarray:
    return cv2.resize(read_picture(path), FRAME)


class Stages:
    """Wall seconds spent in the label's stages (the engine calls them from `learning`)."""

    NAMES = {"write_labelled": "write", "folded_in": "fold-in", "save_models": "save"}

    def __init__(self) -> None:
        self.seconds = dict.fromkeys(self.NAMES.values(), 0.0)

    @contextlib.contextmanager
    def timed(self) -> Iterator[None]:
        originals = {name: getattr(learning, name) for name in self.NAMES}
        for name, original in originals.items():
            setattr(learning, name, self._timing(self.NAMES[name], original))
        try:
            yield
        finally:
            for name, original in originals.items():
                setattr(learning, name, original)

    def _timing(self, stage: str, original: Callable[..., Any]) -> Callable[..., Any]:
        def timed(*args: Any, **kwargs: Any) -> Any:
            start = time.perf_counter()
            try:
                return original(*args, **kwargs)
            finally:
                self.seconds[stage] += time.perf_counter() - start

        return timed


def engine_labels(
    engine: Engine, pictures: list[np.ndarray], places: list[str], what: str, pause: float
) -> None:
    rows = []
    for picture, place in zip(pictures, places, strict=True):
        time.sleep(pause)  # the sense thread goes on between questions
        window = engine._unknowns.keep(Kept("image", picture))
        stages = Stages()
        with stages.timed():
            start, used = time.perf_counter(), time.thread_time()
            engine.label_unknown(window, place)
            wall, spent = time.perf_counter() - start, time.thread_time() - used
        rows.append((wall, spent, stages.seconds))
    print(f"Engine.label_unknown, {what}: wall s / CPU s of the labelling thread (write, fold-in,")
    print("save in wall s)")
    for i, (wall, spent, parts) in enumerate(rows, start=1):
        split = ", ".join(f"{parts[s]:.2f}" for s in Stages.NAMES.values())
        print(f"  label {i:2d}: {wall:5.2f} / {spent:4.2f}   ({split})")
    walls = [row[0] for row in rows]
    print(f"  median {np.median(walls):.2f} s, last {walls[-1]:.2f} s, largest {max(walls):.2f} s")


def sound_labels(shared: Path, engine: Engine, labels: int) -> None:
    """Labels of the sound (not the question's subject in issue 41, measured beside it): 30 s
    a label, as the engine keeps the windows that named no place, from recordings of a street
    the library holds another of, folded into birdnet's head as one more visit each."""
    files = sorted((shared / "audio" / "dev" / "street").iterdir())[1:]
    size = 5 * RATE
    pieces: list[np.ndarray] = []
    for path in files:
        sound, rate = sf.read(path, dtype="float32", always_2d=True)
        sound = resample(sound.mean(axis=1), rate, RATE)
        pieces += [sound[k : k + size] for k in range(0, len(sound) - size + 1, size)]
        if len(pieces) >= 6 * labels:
            break
    rows = []
    for i in range(min(labels, len(pieces) // 6)):
        windows = pieces[6 * i : 6 * i + 6]
        window = engine._unknowns.keep(Kept("audio", windows[-1], RATE, tuple(windows[:-1])))
        start, used = time.perf_counter(), time.thread_time()
        engine.label_unknown(window, "street")
        rows.append((time.perf_counter() - start, time.thread_time() - used))
    print("Engine.label_unknown of 30 s of sound, engine idle: wall s / CPU s")
    print("  " + ", ".join(f"{wall:.2f}/{spent:.2f}" for wall, spent in rows))


def running_engine(shared: Path, root: Path, model: Path) -> Engine:
    """The engine of the app on the saved model, hearing a taught place's other recordings
    and seeing pictures of a place never taught, at real speed."""
    models = load_model(model)
    heard = [Recording("cafe", p) for p in sorted((shared / "audio" / "dev" / "cafe").iterdir())]
    seen = sorted((shared / "images" / "dev" / NEW_PLACE).glob("*.jpg"))[40:80]
    return Engine(
        audio=replay_recordings(heard[1:], RATE, realtime=True, loop=True),
        camera=PictureReplay([Picture(NEW_PLACE, p) for p in seen]),
        acoustic=models.get("acoustic"),
        visual=models.get("visual"),
        library_root=root,
        model_path=model,
    )


async def app_labels(engine: Engine, pictures: list[np.ndarray], places: list[str]) -> None:
    from textual.widgets import Input

    from servant_core.events import UnknownScene
    from servant_tui.app import ServantApp
    from servant_tui.screens.dialogs import LabelPrompt

    def labelled(app: ServantApp) -> int:
        lines = " ".join(line.text for line in app.live.log_view.lines)
        return lines.count("labelled the unknown place")

    app = ServantApp(engine, library_root=engine.library_root)
    walls = []
    async with app.run_test(size=(120, 40)) as pilot:
        await pilot.pause(3)
        for picture, place in zip(pictures, places, strict=True):
            window = engine._unknowns.keep(Kept("image", picture))
            app.question.quiet_until = None  # asked at once, not minutes after the last answer
            app.question.ask(UnknownScene(engine.clock(), "image", "cafe", window))
            while not (isinstance(app.screen, LabelPrompt) and app.screen.query("#scene")):
                await pilot.pause(0.05)
            app.screen.query_one("#scene", Input).value = place
            before, start = labelled(app), time.perf_counter()
            await pilot.press("enter")
            while labelled(app) == before and time.perf_counter() - start < 600:
                await pilot.pause(0.02)
            walls.append(time.perf_counter() - start)
            await pilot.pause(2)
    print("answered in the app (Enter to the log's line), engine running: ", end="")
    print(", ".join(f"{w:.2f}" for w in walls) + f" s (median {np.median(walls):.2f})")


def path_part(shared: Path, labels: int, app: bool) -> None:
    folder = Path(tempfile.mkdtemp(prefix="servant-label-cost-"))
    try:
        root, model = folder / "library", folder / "model.npz"
        teach_mode_library(shared, root)
        engine = Engine(library_root=root, model_path=model)
        start, used = time.perf_counter(), time.process_time()
        engine.retrain(root)
        print(
            f"retrain on the teach-mode library (3 places, 18 recordings, 18 pictures): "
            f"{time.perf_counter() - start:.1f} s, {time.process_time() - used:.1f} CPU s; "
            f"model file {model.stat().st_size / 1e6:.1f} MB"
        )
        retrained = shutil.copy(model, folder / "as-retrained.npz")
        pool = sorted((shared / "images" / "dev" / NEW_PLACE).glob("*.jpg"))
        places = [(NEW_PLACE, *TAUGHT)[i % 4] for i in range(labels)]
        pictures = [frame_of(p) for p in pool[:labels]]
        engine_labels(engine, pictures, places, "engine idle", 0.0)
        sound_labels(shared, engine, labels)
        shutil.copy(retrained, model)
        running = running_engine(shared, root, model)
        running.start()
        try:
            time.sleep(5)
            more = [frame_of(p) for p in pool[labels : 2 * labels]]
            engine_labels(running, more, places, "engine running", 2.0)
        finally:
            running.stop()
            running.join(10)
        if app:
            shutil.copy(retrained, model)
            last = [frame_of(p) for p in pool[2 * labels : 3 * labels]]
            asyncio.run(app_labels(running_engine(shared, root, model), last, places))
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--labels", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--app", action="store_true", help="also answer in the terminal app")
    args = parser.parse_args()
    shared = shared_data()
    if not (shared / "images" / "dev").is_dir() or not (shared / "audio" / "dev").is_dir():
        print(f"no real data at {shared}; nothing to measure")
        return 0
    model_part(shared / "images" / "dev", args.labels, np.random.default_rng(args.seed))
    path_part(shared, args.labels, args.app)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
