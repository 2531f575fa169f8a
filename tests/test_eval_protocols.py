"""`eval audio --test`, `--protocol fewshot --shots`, `--seeds` (audio and image), over small
scene libraries synthesised by the demo's own code (no real data needed)."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import soundfile as sf

from servant_core.cli import main
from servant_core.demo.audio_synth import DEMO_RATE
from servant_core.demo.scenes import synth_picture, synth_window
from servant_core.evaluate import (
    TAUGHT,
    audio_plans,
    fewshot_split,
    seeded_params,
    temporal_split,
)
from servant_core.library import Recording, WindowFeatures

SCENES = ("coffee", "gym", "street")


def synth_library(root, seed, recordings=2, windows=6, pictures=0):
    """ROOT/<scene>/rec<i>.wav of `windows` 5 s windows each (+ `pictures` PNGs per scene)."""
    for s, scene in enumerate(SCENES):
        folder = root / scene
        folder.mkdir(parents=True)
        for r in range(recordings):
            sound = np.concatenate(
                [
                    synth_window(scene, np.random.default_rng([seed, s, r, w]))
                    for w in range(windows)
                ]
            )
            sf.write(folder / f"rec{r}.wav", sound, DEMO_RATE)
        for p in range(pictures):
            image = synth_picture(scene, np.random.default_rng([seed, s, 99, p]))
            cv2.imwrite(str(folder / f"p{p:02d}.png"), image)
    return root


@pytest.fixture(scope="module")
def libraries(tmp_path_factory):
    base = tmp_path_factory.mktemp("synth")
    return synth_library(base / "a", 1, pictures=5), synth_library(base / "b", 2, recordings=1)


def run_json(capsys, *argv):
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_fewshot_split_takes_the_first_k_windows_inside_the_temporal_train_part():
    recording = np.array([0] * 5 + [1] * 10)
    position = np.concatenate([np.arange(5), np.arange(10)])
    # recording 0: 3 windows train temporally, so k=5 stops at 3; recording 1: 6 train
    assert fewshot_split(recording, position, 2).tolist() == (
        [True] * 2 + [False] * 3 + [True] * 2 + [False] * 8
    )
    assert fewshot_split(recording, position, 5).tolist() == (
        [True] * 3 + [False] * 2 + [True] * 5 + [False] * 5
    )
    assert not np.any(fewshot_split(recording, position, 10) & ~temporal_split(recording, position))


def test_eval_audio_trains_on_one_library_and_tests_on_another(libraries, capsys):
    a, b = libraries
    result = run_json(
        capsys, "eval", "audio", str(a), "--test", str(b), "--method", "codebook", "--rate", "8000"
    )
    assert result["protocol"] == "train-test"
    assert result["n_train"] == 3 * 2 * 6 and result["n_test"] == 3 * 1 * 6
    # every test window comes from the other library
    assert set(result["per_recording"]) == {f"{s}/rec0.wav" for s in SCENES}
    assert sum(sum(r["heard_as"].values()) for r in result["per_recording"].values()) == 18


def test_eval_audio_fewshot_gives_one_row_per_k(libraries, capsys):
    a, _ = libraries
    argv = ["eval", "audio", str(a), "--protocol", "fewshot", "--shots", "1,3"]
    argv += ["--method", "codebook", "--rate", "8000"]
    result = run_json(capsys, *argv)
    assert result["protocol"] == "fewshot"
    assert [row["shots"] for row in result["rows"]] == [1, 3]
    # 6 recordings: k windows each train; the temporal test part (6 - 3 windows each) tests
    assert [row["n_train"] for row in result["rows"]] == [6, 18]
    assert [row["n_test"] for row in result["rows"]] == [18, 18]
    main(argv)
    lines = capsys.readouterr().out.splitlines()
    assert lines[1].startswith("k=1 ") and lines[2].startswith("k=3 ") and len(lines) == 3


def test_eval_audio_seeds_report_mean_spread_and_each_seed(libraries, capsys):
    a, _ = libraries
    result = run_json(
        capsys, "eval", "audio", str(a), "--method", "codebook", "--seeds", "3", "--rate", "8000"
    )
    per_seed = result["per_seed"]
    assert [s["random_state"] for s in per_seed] == [0, 1, 2] and result["seeds"] == 3
    values = [s["balanced_accuracy"] for s in per_seed]
    assert result["balanced_accuracy"] == pytest.approx(np.mean(values))
    spread = result["spread"]["balanced_accuracy"]
    assert spread["min"] == min(values) and spread["max"] == max(values)
    assert spread["std"] == pytest.approx(np.std(values))
    main(["eval", "audio", str(a), "--method", "codebook", "--seeds", "2", "--rate", "8000"])
    assert "std " in capsys.readouterr().out


def test_seeds_reach_the_methods_random_state():
    seeded = seeded_params({"rate": 8000}, "codebook", "audio", 3)
    assert seeded == {"rate": 8000, "random_state": 3}
    assert seeded_params({"rate": 8000}, "codebook", "audio", None) == {"rate": 8000}


def test_eval_image_seeds(libraries, capsys):
    a, _ = libraries
    result = run_json(capsys, "eval", "image", str(a), "--method", "bovw", "--seeds", "2")
    assert [s["random_state"] for s in result["per_seed"]] == [0, 1]
    assert result["balanced_accuracy"] == pytest.approx(
        np.mean([s["balanced_accuracy"] for s in result["per_seed"]])
    )


def test_test_with_another_protocol_says_what_to_do(libraries, capsys):
    a, b = libraries
    argv = ["eval", "audio", str(a), "--rate", "8000", "--test", str(b), "--protocol", "recording"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("servant: error:") and "--test" in err and err.count("\n") == 1


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--protocol", "fewshot", "--shots", "0,2"], "at least 1"),
        (["--seeds", "0"], "--seeds: '0' is not between 1 and 100"),
    ],
)
def test_bad_shots_and_seeds_are_refused_by_the_parser(libraries, capsys, argv, says):
    a, _ = libraries
    with pytest.raises(SystemExit) as exit_:
        main(["eval", "audio", str(a), *argv])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("servant: error:") and says in err and err.count("\n") == 1


def test_eval_audio_follows_every_fold_after_the_listening(libraries):
    """After the listening's bar came a silence of minutes while the folds trained (issue 22):
    each model fitted and tested is now counted, to the total of folds times seeds."""
    from servant_core.evaluate import evaluate_audio
    from servant_core.library import SceneLibrary

    seen: list[tuple[int, int]] = []
    result = evaluate_audio(
        SceneLibrary.scan(libraries[0]),
        "kmeans-encoder",
        "recording",
        seeds=2,
        on_fold=lambda done, total: seen.append((done, total)),
    )
    folds = 2 * len(SCENES)  # a model for each recording left out, for each seed
    assert seen == [(k, folds * 2) for k in range(1, folds * 2 + 1)]
    assert result["seeds"] == 2


def windows_of(lengths):
    """WindowFeatures of recordings of {scene: [windows of each recording]} (features unused)."""
    recordings, scenes, recording, position = [], [], [], []
    for scene, sizes in lengths.items():
        for n in sizes:
            scenes += [scene] * n
            recording += [len(recordings)] * n
            position += list(range(n))
            recordings.append(Recording(scene, Path(f"{scene}/r{len(recordings)}.wav")))
    features = np.zeros((len(scenes), 2))
    return WindowFeatures(
        features, np.array(scenes), np.array(recording), np.array(position), recordings
    )


def test_taught_tests_every_teach_sample_beside_a_longer_recording():
    """Issue 39 item 5: a library of teach mode's 5 s samples with one longer recording was
    evaluated on the longer recording's later windows alone (3 test windows, one place): every
    recording is left out and tested in turn."""
    wf = windows_of({"cafe": [1, 1, 1, 4], "street": [1, 1, 1]})
    (plan,) = audio_plans(wf, TAUGHT)
    assert plan.protocol == "recording" and len(plan.tests) == len(wf.recordings)
    assert np.logical_or.reduce(plan.tests).all()
    # longer recordings only: their later part is the test, as before
    (plan,) = audio_plans(windows_of({"cafe": [4, 4], "street": [4]}), TAUGHT)
    assert plan.protocol == "temporal"
    # a place with a single sample cannot be left out: the later part of the longer one
    (plan,) = audio_plans(windows_of({"cafe": [1, 4], "street": [1]}), TAUGHT)
    assert plan.protocol == "temporal"
