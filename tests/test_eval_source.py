"""`eval audio --protocol source`: leave one source out (the file name up to its first `-`, or a
`--groups` file), and `--min-recordings`. A source must never be on both sides of a fold."""

import json
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from servant_core.cli import main
from servant_core.evaluate import audio_plans, read_groups, source_of
from servant_core.library import Recording, WindowFeatures
from tests.conftest import link_library

RATE = 8000
WINDOWS = 3
# Each source's recordings carry its own tone over noise no scene shapes: the tone names the
# source, and through it the scene, only for a model that has heard that source before. The
# tones alternate scenes up the scale, so a tone never heard lies between the other scene's.
SOURCE_TONES = {"alpha": ("coffee", 400.0), "beta": ("street", 800.0)}
SOURCE_TONES |= {"gamma": ("coffee", 1600.0), "delta": ("street", 3200.0)}


def fingerprint_library(root):
    """ROOT/<scene>/<source>-<i>.wav: two recordings of each source, tone + white noise."""
    for s, (source, (scene, freq)) in enumerate(SOURCE_TONES.items()):
        (root / scene).mkdir(parents=True, exist_ok=True)
        for i in range(2):
            rng = np.random.default_rng([s, i])
            t = np.arange(WINDOWS * 5 * RATE) / RATE
            sound = 0.3 * np.sin(2 * np.pi * freq * t) + 0.1 * rng.standard_normal(len(t))
            sf.write(root / scene / f"{source}-{i}.wav", sound.astype(np.float32), RATE)
    return root


@pytest.fixture(scope="module")
def fingerprints(tmp_path_factory):
    return fingerprint_library(tmp_path_factory.mktemp("fingerprints"))


def run_json(capsys, *argv):
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def eval_argv(root, *more):
    return ["eval", "audio", str(root), "--method", "codebook", "--rate", str(RATE), *more]


@pytest.mark.parametrize(
    ("name", "source"),
    [
        ("cafe/moodist-crowded-bar.mp3", "moodist"),
        ("cafe/suneung-timer-nati-cafe-9100abf.mp3", "suneung"),
        ("street/audionova-street-a17ffce.mp3", "audionova"),
        ("vehicle/rec0.wav", "rec0"),
    ],
)
def test_a_recordings_source_is_its_file_name_up_to_the_first_dash(name, source):
    assert source_of(Path(name)) == source


def test_source_folds_hold_each_source_out_whole_and_test_every_window_once():
    names = ["a/x-1.wav", "a/y-1.wav", "b/x-2.wav", "b/z-1.wav", "b/y-2.wav"]
    recordings = [Recording(n.split("/")[0], Path(n)) for n in names]
    recording = np.repeat(np.arange(5), [2, 3, 1, 2, 2])
    wf = WindowFeatures(
        np.zeros((len(recording), 1)),
        np.array([recordings[r].scene for r in recording]),
        recording,
        np.zeros(len(recording), int),
        recordings,
    )
    (plan,) = audio_plans(wf, "source")
    assert plan.left_out == ["x", "y", "z"]
    source = np.array([source_of(r.path) for r in recordings])[recording]
    for left_out, train, test in zip(plan.left_out, plan.folds, plan.tests, strict=True):
        assert set(source[test]) == {left_out} and left_out not in set(source[train])
        assert np.all(train == ~test)
    assert np.array_equal(np.sum(plan.tests, axis=0), np.ones(len(recording)))
    # a groups list overrides the file names: two groups, two folds
    (plan,) = audio_plans(wf, "source", groups=["g", "g", "h", "h", "g"])
    assert plan.left_out == ["g", "h"]
    assert plan.tests[0].tolist() == np.isin(recording, [0, 1, 4]).tolist()


def test_leave_one_source_out_never_trains_on_the_source_it_tests(fingerprints, capsys):
    by_source = run_json(capsys, *eval_argv(fingerprints, "--protocol", "source"))
    by_recording = run_json(capsys, *eval_argv(fingerprints, "--protocol", "recording"))
    assert by_source["protocol"] == "source"
    folds = {f["left_out"]: f for f in by_source["folds"]}
    assert set(folds) == set(SOURCE_TONES)
    total = 2 * len(SOURCE_TONES) * WINDOWS
    for source, (scene, _) in SOURCE_TONES.items():
        fold = folds[source]
        assert fold["recordings"] == [f"{scene}/{source}-{i}.wav" for i in range(2)]
        # the fold trains on every window but its own source's two recordings
        assert fold["n_test"] == 2 * WINDOWS and fold["n_train"] == total - 2 * WINDOWS
        assert fold["unseen_scenes"] == []
    assert by_source["n_test"] == total and by_source["n_train"] == len(SOURCE_TONES) * (
        total - 2 * WINDOWS
    )
    # A recording's twin from its source gives its tone away; a source never heard does not.
    assert by_recording["balanced_accuracy"] >= 0.9
    assert by_source["balanced_accuracy"] <= 0.5


def test_a_groups_file_sets_the_folds(fingerprints, tmp_path, capsys):
    groups = tmp_path / "groups.txt"
    groups.write_text(
        "# recording  group\n"
        "coffee/alpha-0.wav  one\ncoffee/alpha-1.wav one\n"
        f"{fingerprints / 'street' / 'beta-0.wav'}\tone\nstreet/beta-1.wav one\n\n"
        "coffee/gamma-0.wav two\ncoffee/gamma-1.wav two\n"
        "street/delta-0.wav two\nstreet/delta-1.wav two\n"
    )
    result = run_json(
        capsys, *eval_argv(fingerprints, "--protocol", "source", "--groups", str(groups))
    )
    assert [f["left_out"] for f in result["folds"]] == ["one", "two"]
    assert result["folds"][0]["recordings"] == [
        "coffee/alpha-0.wav",
        "coffee/alpha-1.wav",
        "street/beta-0.wav",
        "street/beta-1.wav",
    ]
    main(eval_argv(fingerprints, "--protocol", "source", "--groups", str(groups)))
    assert "left out in turn" in capsys.readouterr().out


def test_read_groups_parses_paths_with_spaces_and_refuses_what_it_cannot_place(tmp_path):
    root = tmp_path / "lib"
    groups = tmp_path / "g.txt"
    groups.write_text(f"cafe/my rec-1.wav  home\n{root / 'street' / 'x.wav'} away\n")
    assert read_groups(groups, root) == {"cafe/my rec-1.wav": "home", "street/x.wav": "away"}
    groups.write_text("lonely\n")
    with pytest.raises(Exception, match=r"g.txt:1: expected a recording's path"):
        read_groups(groups, root)
    groups.write_text("/elsewhere/x.wav home\n")
    with pytest.raises(Exception, match="not below the scene library"):
        read_groups(groups, root)


@pytest.mark.parametrize(
    ("more", "says"),
    [
        (["--groups", "GROUPS"], "--groups names the groups of --protocol source"),
        (["--protocol", "source", "--groups", "GROUPS"], "no group for coffee/alpha-1.wav"),
        (["--min-recordings", "9"], "no scene has 9 recordings or more"),
    ],
)
def test_source_options_say_what_is_wrong(fingerprints, tmp_path, capsys, more, says):
    groups = tmp_path / "groups.txt"
    groups.write_text("coffee/alpha-0.wav one\n")
    argv = eval_argv(fingerprints, *(str(groups) if m == "GROUPS" else m for m in more))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("servant: error:") and says in err and err.count("\n") == 1


def test_one_source_alone_has_nothing_to_leave_out(fingerprints, tmp_path, capsys):
    groups = tmp_path / "groups.txt"
    groups.write_text(
        "".join(
            f"{scene}/{source}-{i}.wav all\n"
            for source, (scene, _) in SOURCE_TONES.items()
            for i in range(2)
        )
    )
    assert main(eval_argv(fingerprints, "--protocol", "source", "--groups", str(groups))) == 2
    assert "fewer than two scenes" in capsys.readouterr().err


# Short real recordings from five sources; every source but csesoc crosses scenes, and audionova
# has two street recordings: leaving out one recording would train on its twin.
REAL = {
    "cafe": (
        [
            "moodist-crowded-bar.mp3",
            "dusktide-cast-cafe.mp3",
            "csesoc-hackathon-c-cafe.mp3",
            "audionova-restaurant.mp3",
        ],
        0,
    ),
    "street": (
        [
            "audionova-street.mp3",
            "audionova-street-a17ffce.mp3",
            "moodist-traffic.mp3",
            "dusktide-cast-city.mp3",
        ],
        0,
    ),
    "park": (["datameditation-park.mp3"], 0),
}


def test_leave_one_source_out_on_real_recordings(shared_data, tmp_path, capsys):
    root = link_library(tmp_path / "lib", shared_data, REAL)
    result = run_json(capsys, *eval_argv(root, "--protocol", "source", "--min-recordings", "2"))
    assert set(result["per_class"]) == {"cafe", "street"}  # park has one recording
    folds = {f["left_out"]: f for f in result["folds"]}
    assert set(folds) == {"audionova", "csesoc", "dusktide", "moodist"}
    assert folds["audionova"]["recordings"] == [
        "cafe/audionova-restaurant.mp3",
        "street/audionova-street-a17ffce.mp3",
        "street/audionova-street.mp3",
    ]
    windows = {name: sum(r["heard_as"].values()) for name, r in result["per_recording"].items()}
    total = sum(windows.values())
    for source, fold in folds.items():
        assert all(name.split("/")[1].startswith(f"{source}-") for name in fold["recordings"])
        assert fold["n_test"] == sum(windows[name] for name in fold["recordings"])
        assert fold["n_train"] == total - fold["n_test"]
