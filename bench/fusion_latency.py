"""How soon after entering a scene does each fusion policy decide, and is it right?

Streams built from the real data (scenes with both recordings and pictures): the user enters a
scene at t = 0; an acoustic prediction arrives at the end of every 5 s window (consecutive test
windows of one recording, after the temporal split), and a picture is taken whenever the policy
asks (test pictures of the same scene after the 70/30 file-order split, predicted by the visual
method). One encounter starts at every test window; it ends at the first decision.

    python bench/fusion_latency.py [--audio-method codebook] [--image-method bovw] [--pictures 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from common import shared_data  # noqa: E402

from servant_core.evaluate import fit_paired  # noqa: E402
from servant_core.events import Decision  # noqa: E402
from servant_core.fusion import POLICIES, FusionConfig  # noqa: E402
from servant_core.library import SceneLibrary  # noqa: E402

HORIZON_S = 60.0
STEP_S = 0.5


def paired_library(root: Path) -> SceneLibrary:
    """Scenes with both sound and pictures, as symbolic links (nothing is copied)."""
    data = shared_data()
    audio = SceneLibrary.scan(data / "audio" / "dev")
    images = SceneLibrary.scan(data / "images" / "dev")
    for scene in sorted(set(audio.scenes) & set(images.scenes)):
        (root / scene).mkdir()
        for item in [*audio.recordings, *images.pictures]:
            if item.scene == scene:
                (root / scene / item.path.name).symlink_to(item.path)
    return SceneLibrary.scan(root)


def encounter(policy, sounds, pictures, window_s: float) -> Decision | None:
    shown = 0
    for step in range(int(HORIZON_S / STEP_S) + 1):
        t = step * STEP_S
        events = policy.tick(t)
        k = int(round(t / window_s))
        if t > 0 and abs(t - k * window_s) < 1e-9 and k <= len(sounds):
            events += policy.on_acoustic(*sounds[k - 1], t)
        if policy.wants_picture(t):
            events += policy.on_visual(*pictures[shown % len(pictures)], t)
            shown += 1
        for event in events:
            if isinstance(event, Decision):
                return event
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--audio-method", default="codebook")
    parser.add_argument("--image-method", default="bovw")
    parser.add_argument("--pictures", type=int, default=FusionConfig().pictures_needed)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        library = paired_library(Path(tmp))
        fitted = fit_paired(library, args.audio_method, args.image_method, None)
    audio, wf, train = fitted.audio, fitted.windows, fitted.window_train
    visual, X, kept, p_train = (
        fitted.visual,
        fitted.picture_features,
        fitted.pictures,
        fitted.picture_train,
    )
    test = ~train
    a_scene, a_conf = audio.predict(wf.features[test]), audio.confidence(wf.features[test])
    v_rows = np.flatnonzero(~p_train)
    v_scene, v_conf = visual.predict(X[v_rows]), visual.confidence(X[v_rows])
    pictures: dict[str, list[tuple[str, float]]] = {}
    for k, i in enumerate(v_rows):
        pictures.setdefault(kept[i].scene, []).append((str(v_scene[k]), float(v_conf[k])))
    recording, truth = wf.recording[test], wf.scenes[test]
    results = {}
    for name, policy_class in sorted(POLICIES.items()):
        times, right, decided = [], 0, 0
        for i in range(len(truth)):
            later = [j for j in range(i, len(truth)) if recording[j] == recording[i]]
            sounds = [(str(a_scene[j]), float(a_conf[j])) for j in later]
            pics = pictures[truth[i]]
            start = (i * 3) % len(pics)
            decision = encounter(
                policy_class(FusionConfig(pictures_needed=args.pictures)),
                sounds,
                pics[start:] + pics[:start],
                audio.window_seconds,
            )
            if decision is not None and decision.scene is not None:
                decided += 1
                right += decision.scene == truth[i]
                times.append(decision.t)
        results[name] = {
            "encounters": len(truth),
            "decided": decided / len(truth),
            "right_when_decided": right / decided if decided else 0.0,
            "median_s": statistics.median(times) if times else None,
            "p90_s": float(np.quantile(times, 0.9)) if times else None,
        }
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"{'policy':<12}{'decided':>9}{'right':>8}{'median s':>10}{'p90 s':>8}")
    for name, r in results.items():
        print(
            f"{name:<12}{r['decided']:>9.3f}{r['right_when_decided']:>8.3f}"
            f"{r['median_s']:>10.1f}{r['p90_s']:>8.1f}"
        )


if __name__ == "__main__":
    main()
