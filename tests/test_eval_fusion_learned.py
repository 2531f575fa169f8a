"""`eval fusion --policy learned [--drop-sense S] [--seeds N]`, `train --learned-fusion` and
`predict --policy learned`, over a small library synthesised by the demo's own code."""

import json

import pytest

from servant_core.cli import main
from servant_core.evaluate import fusion_setup, score_fusion, score_learned
from servant_core.fusion import FusionConfig, ParallelFusion
from servant_core.library import SceneLibrary
from servant_core.modelfile import load_model_and_fusion
from tests.test_eval_protocols import synth_library

# The cheaper acoustic method: the fusion is under test here, not the recogniser.
METHODS = ("--audio-method", "codebook", "--image-method", "bovw")


@pytest.fixture(scope="module")
def library(tmp_path_factory):
    return synth_library(tmp_path_factory.mktemp("synth") / "lib", 1, windows=8, pictures=8)


@pytest.fixture(scope="module")
def setup(library):
    return fusion_setup(SceneLibrary.scan(library), "codebook", "bovw")


def run_json(capsys, *argv):
    assert main([*argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_learned_fusion_decides_with_both_senses_and_with_either_alone(setup):
    config = FusionConfig()
    both = score_learned(setup, config, seeds=2)
    assert both["seeds"] == 2 and len(both["per_seed"]) == 2
    assert all(r["fallback"] is None and 0 < r["threshold"] < 1 for r in both["per_seed"])
    assert both["decision_rate"] >= 0.8 and both["precision"] >= 0.9
    assert set(both["n_train"]) == {"audio", "image"}
    for sense, other in (("audio", "image"), ("image", "audio")):
        alone = score_learned(setup, config, sense)
        assert alone["decision_rate"] > 0.5
        assert set(alone["leaned_on"]) == {other}  # the withheld sense was never leaned on
        rule = score_fusion(setup, lambda: ParallelFusion(config), config, sense)
        assert rule["decision_rate"] == 0.0  # the rules need both senses


def test_eval_fusion_learned_without_a_sense_from_the_command_line(library, capsys):
    result = run_json(
        capsys,
        "eval",
        "fusion",
        str(library),
        *METHODS,
        "--policy",
        "learned",
        "--drop-sense",
        "audio",
    )
    assert result["policy"] == "learned" and result["drop_sense"] == "audio"
    assert result["decision_rate"] > 0.5 and set(result["leaned_on"]) == {"image"}


def test_a_sense_that_is_not_one_is_refused(library, capsys):
    with pytest.raises(SystemExit) as info:
        main(["eval", "fusion", str(library), *METHODS, "--drop-sense", "motion"])
    assert info.value.code == 2
    assert "invalid choice: 'motion'" in capsys.readouterr().err


def test_train_saves_the_net_and_predict_uses_it(library, tmp_path, capsys):
    model = tmp_path / "m.npz"
    summary = run_json(
        capsys, "train", str(library), "-o", str(model), *METHODS, "--learned-fusion"
    )
    assert summary["fusion"]["senses"] == ["audio", "image"]
    recognisers, net = load_model_and_fusion(model)
    assert net is not None and net.threshold_ == summary["fusion"]["threshold"]
    result = run_json(
        capsys,
        "predict",
        str(model),
        "--audio",
        str(library / "gym" / "rec1.wav"),
        "--image",
        str(library / "gym" / "p07.png"),
        "--policy",
        "learned",
    )
    assert result["decision"]["scene"] == "gym"
    assert result["decision"]["leaned_on"]  # which senses it rested on is said
