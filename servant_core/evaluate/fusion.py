"""Scoring a fusion policy: each test window of a scene meets that scene's test pictures, in
turn, through a fresh decision pipeline around the policy (`evaluate_fusion`, `servant eval
fusion`); how often it decides and, when it names a scene, how often it is right.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Collection, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from servant_core.errors import ServantError
from servant_core.evaluate.metrics import averaged
from servant_core.evaluate.paired import PairedFit, fit_paired, paired_scenes
from servant_core.events import Decision
from servant_core.fusion import (
    POLICIES,
    FusionConfig,
    FusionNet,
    LearnedFusion,
    scene_line,
)
from servant_core.fusion.learning import (
    DEFAULT_FOLDS,
    picture_opinions,
    train_fusion_net,
    window_opinions,
)
from servant_core.fusion.net import SenseOpinions
from servant_core.fusion.pipeline import DecisionPipeline, Said
from servant_core.library import SceneLibrary, WindowFeatures
from servant_core.recognisers import UNKNOWN, Recogniser
from servant_core.recognisers.base import knows_elsewhere, open_predict, open_probabilities

SENSES = ("audio", "image")


def run_encounter(
    policy: Any,
    config: FusionConfig,
    acoustic: Said | None,
    visual: Sequence[Said],
    open_roles: Collection[str] = (),
) -> Decision:
    """One scene encounter through a fresh decision pipeline around `policy`
    (`DecisionPipeline.encounter`): what the live engine would decide of these opinions."""
    return DecisionPipeline(policy).encounter(config, acoustic, visual, open_roles)


def run_fusion(
    policy_name: str,
    config: FusionConfig,
    acoustic: tuple[str, float],
    visual: Sequence[tuple[str, float]],
) -> Any:
    """One scene encounter through a rule policy (see `run_encounter`). Returns the Decision."""
    if acoustic[0] == UNKNOWN:
        # An unknown place opens no window in any policy: nothing to confirm, no decision.
        return Decision(0.0, None, 0.0, scene_line(None))
    return run_encounter(
        POLICIES[policy_name](config),
        config,
        (*acoustic, None),
        [(*v, None) for v in visual],
    )


def said_of(model: Recogniser, X: np.ndarray) -> list[Said]:
    """Each row's opinion: scene, confidence and probability per scene (and not somewhere
    else, where the recogniser knows somewhere else)."""
    scenes, confidences = open_predict(model, X), model.confidence(X)
    proba = open_probabilities(model, X)
    return [
        (
            str(scenes[i]),
            float(confidences[i]),
            dict(zip(model.scenes_, map(float, proba[i]), strict=True)),
        )
        for i in range(len(scenes))
    ]


def fusion_opinions(fitted: PairedFit, folds: int = DEFAULT_FOLDS) -> dict[str, SenseOpinions]:
    """Each sense's held-out opinions of its own training part (see
    `servant_core.fusion.learning`): what the learned fusion is trained on."""
    wf, train = fitted.windows, fitted.window_train
    windows = WindowFeatures(
        wf.features[train], wf.scenes[train], wf.recording[train], wf.position[train], wf.recordings
    )
    p_train = np.flatnonzero(fitted.picture_train)
    return {
        "audio": window_opinions(fitted.audio, windows, folds),
        "image": picture_opinions(
            fitted.visual,
            fitted.picture_features[p_train],
            [fitted.pictures[i] for i in p_train],
            folds,
        ),
    }


FUSION_METRICS = ("decision_rate", "precision", "accuracy")


@dataclass
class FusionSetup:
    """What a fusion evaluation runs encounters from: each test window's acoustic opinion and
    its true scene, each scene's test pictures' opinions, and (for the learned fusion) each
    sense's held-out opinions of the training parts."""

    scenes: list[str]
    truth: np.ndarray
    acoustic: list[Said]
    pictures: dict[str, list[Said]]
    opinions: dict[str, SenseOpinions] | None = None
    open_roles: frozenset[str] = frozenset()  # the roles whose recogniser knows elsewhere


def fusion_setup(
    library: SceneLibrary,
    acoustic_method: str,
    visual_method: str,
    on_error: Callable[[ServantError], None] | None = None,
    folds: int | None = DEFAULT_FOLDS,
) -> FusionSetup:
    """Fit both recognisers on the training parts of `library`'s paired scenes and judge the
    test parts; with `folds`, also the held-out opinions the learned fusion trains on."""
    paired = paired_scenes(library, None, "fusion needs")
    fitted = fit_paired(library.restricted(paired), acoustic_method, visual_method, on_error)
    wf, train = fitted.windows, fitted.window_train
    test_pics = [i for i, t in enumerate(fitted.picture_train) if not t]
    visual = said_of(fitted.visual, fitted.picture_features[test_pics])
    pictures: dict[str, list[Said]] = {}
    for k, i in enumerate(test_pics):
        pictures.setdefault(fitted.pictures[i].scene, []).append(visual[k])
    return FusionSetup(
        paired,
        wf.scenes[~train],
        said_of(fitted.audio, wf.features[~train]),
        pictures,
        fusion_opinions(fitted, folds) if folds else None,
        frozenset(
            role
            for role, recogniser in (("acoustic", fitted.audio), ("visual", fitted.visual))
            if knows_elsewhere(recogniser)
        ),
    )


def score_fusion(
    setup: FusionSetup,
    make_policy: Callable[[], Any],
    config: FusionConfig,
    drop_sense: str | None = None,
) -> dict[str, Any]:
    """Each test window meets its scene's test pictures, in turn, through a fresh policy;
    `drop_sense` withholds that sense. Decision rate, precision, accuracy, and which senses the
    decisions leaned on."""
    decided = right = 0
    leaned: Counter[str] = Counter()
    cursor = dict.fromkeys(setup.pictures, 0)
    for i, scene in enumerate(setup.truth):
        # a scene whose pictures all went to training (one picture) shows its windows none
        pics = setup.pictures.get(scene, [])
        start = cursor.get(scene, 0)
        shown = [pics[(start + j) % len(pics)] for j in range(len(pics))]
        if pics:
            cursor[scene] = (start + config.pictures_needed) % len(pics)
        heard = None if drop_sense == "audio" else setup.acoustic[i]
        decision = run_encounter(
            make_policy(), config, heard, [] if drop_sense == "image" else shown, setup.open_roles
        )
        if decision.scene is not None:
            decided += 1
            right += decision.scene == scene
            leaned.update(["+".join(decision.leaned_on) or "-"])
    n = len(setup.truth)
    return {
        "decision_rate": decided / n if n else 0.0,
        "precision": right / decided if decided else 0.0,
        "accuracy": right / n if n else 0.0,
        "leaned_on": dict(leaned.most_common()),
    }


def score_learned(
    setup: FusionSetup, config: FusionConfig, drop_sense: str | None = None, seeds: int = 1
) -> dict[str, Any]:
    """The learned fusion over net random states 0..seeds-1: each seed's net is trained on the
    setup's held-out opinions; one seed's figures, or their mean, spread and `per_seed`."""
    if setup.opinions is None:
        raise ValueError("the learned fusion needs a setup made with folds")
    runs = []
    for seed in range(seeds):
        net, reason = train_fusion_net(setup.opinions, random_state=seed)

        def make_policy(net: FusionNet | None = net) -> LearnedFusion:
            return LearnedFusion(config, net)

        row = score_fusion(setup, make_policy, config, drop_sense)
        row.update(
            random_state=seed,
            threshold=net.threshold_ if net is not None else None,
            fallback=reason,
        )
        runs.append(row)
    result = dict(runs[0])
    result["n_train"] = {sense: len(o.truth) for sense, o in setup.opinions.items()}
    if seeds > 1:
        result.pop("random_state")
        result["seeds"] = seeds
        result["per_seed"] = runs
        averaged(result, runs, FUSION_METRICS)
    return result


def evaluate_fusion(
    library: SceneLibrary,
    acoustic_method: str = "paper",
    visual_method: str = "paper",
    policy: str = "sequential",
    config: FusionConfig | None = None,
    on_error: Callable[[ServantError], None] | None = None,
    *,
    drop_sense: str | None = None,
    seeds: int = 1,
    folds: int = DEFAULT_FOLDS,
) -> dict[str, Any]:
    """Each test window (temporal split) of a scene that also has pictures is paired with that
    scene's test pictures (file-order split), in turn; the policy decides or not. Reports how
    often it decides and, when it names a scene, how often it is right.

    `learned`: the net is trained on each sense's held-out opinions of the training parts
    (`fusion_opinions`), over net random states 0..seeds-1 (mean, spread, per seed).
    `drop_sense` ("audio" or "image") withholds that sense at test time."""
    if policy not in POLICIES:
        raise ServantError(
            f"unknown fusion policy {policy!r}; choose {', '.join(sorted(POLICIES))}"
        )
    if drop_sense is not None and drop_sense not in SENSES:
        raise ServantError(f"no sense named {drop_sense!r} to drop; choose {', '.join(SENSES)}")
    if seeds < 1:
        raise ServantError(f"--seeds must be at least 1, not {seeds}")
    config = config or FusionConfig()
    learned = policy == "learned"
    setup = fusion_setup(
        library, acoustic_method, visual_method, on_error, folds if learned else None
    )
    result: dict[str, Any] = {
        "method": f"{acoustic_method}+{visual_method}",
        "acoustic_method": acoustic_method,
        "visual_method": visual_method,
        "policy": policy,
        "protocol": "temporal+file-order",
        "scenes": setup.scenes,
        "n_test": len(setup.truth),
        "drop_sense": drop_sense,
    }
    if learned:
        result.update(score_learned(setup, config, drop_sense, seeds))
    else:
        result.update(score_fusion(setup, lambda: POLICIES[policy](config), config, drop_sense))
    return result
