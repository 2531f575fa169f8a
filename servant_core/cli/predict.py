"""`servant predict`: the place of each window of a recording and of each picture, and the
decision the live engine would make from them."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, cast

import numpy as np

from servant_core.audio import SILENT_DBFS, cut_windows, is_silent, read_audio
from servant_core.cli import emit
from servant_core.cli.recognition import policy_config, warn
from servant_core.engine import decision_unit
from servant_core.errors import ServantError
from servant_core.evaluate import Said, run_encounter, said_of
from servant_core.event_text import confidence_text, place
from servant_core.features.rows import checked_rows, usable_rows
from servant_core.fusion import POLICIES, FusionNet, LearnedFusion
from servant_core.fusion.elsewhere import beside_open_sound, shown
from servant_core.library import read_picture
from servant_core.modelfile import load_model_and_fusion
from servant_core.recognisers import UNKNOWN, AcousticRecogniser, Recogniser
from servant_core.recognisers.base import knows_elsewhere, open_predict, open_probabilities


def cmd_predict(args: argparse.Namespace) -> int:
    """`servant predict`: name the place of each window of `--audio` and of each `--image`
    picture, and, given both, the decision the live engine would make from the recording's
    first window and the pictures."""
    if args.audio is None and not args.image:
        raise ServantError("give --audio FILE and/or --image FILE...")
    model, fusion = load_model_and_fusion(args.model)
    result: dict[str, Any] = {}
    lines: list[str] = []
    first_acoustic: Said | None = None
    if args.audio is not None:
        result["acoustic"], heard, first_acoustic = _predict_audio(args, model)
        lines += heard
    visual_predictions: list[Said] = []
    if args.image:
        result["visual"], seen, visual_predictions = _predict_pictures(args, model)
        lines += seen
    if first_acoustic is not None and visual_predictions:
        result["decision"], decided = _predict_decision(
            args, model, fusion, first_acoustic, visual_predictions
        )
        lines.append(decided)
    emit(args, result, "\n".join(lines))
    return 0


def _predict_audio(
    args: argparse.Namespace, model: dict[str, Recogniser]
) -> tuple[list[dict[str, Any]], list[str], Said]:
    """The place of each window of `--audio` that can name one: as JSON rows, as lines, and the
    first such window's opinion (for the decision)."""
    audio = cast(AcousticRecogniser, _role(model, "acoustic", args.model))
    seconds = audio.window_seconds
    X, usable = _usable_windows(args.audio, audio)
    scenes, confidences = open_predict(audio, X), audio.confidence(X)
    unit = audio.confidence_unit
    judged = list(zip(np.flatnonzero(usable).tolist(), scenes, confidences, strict=True))
    rows = [
        {
            "window": i,
            "start_s": i * seconds,
            "end_s": (i + 1) * seconds,
            "scene": str(s),
            "confidence": float(c),
            "confidence_unit": unit,
        }
        for i, s, c in judged
    ]
    lines = [
        f"Acoustic window {i} ({i * seconds:g}-{(i + 1) * seconds:g} s): "
        + _judged(str(s), float(c), unit)
        for i, s, c in judged
    ]
    first: Said = (
        str(scenes[0]),
        float(confidences[0]),
        dict(zip(audio.scenes_, map(float, open_probabilities(audio, X)[0]), strict=True)),
    )
    return rows, lines, first


def _usable_windows(path: Path, audio: AcousticRecogniser) -> tuple[np.ndarray, np.ndarray]:
    """The features of the recording's windows that can name a place, and which windows those
    are (a mask over all of them). Refuses a recording shorter than a window, all silence or with
    no finite features; warns of the windows left out."""
    rate, seconds = audio.rate, audio.window_seconds
    windows = cut_windows(read_audio(path, rate), rate, seconds)
    if len(windows) == 0:
        raise ServantError(f"{path}: shorter than one {seconds:g} s window; record longer")
    silent = np.array([is_silent(w) for w in windows])
    if np.all(silent):
        raise ServantError(
            f"{path}: silence (below {SILENT_DBFS:.0f} dBFS) from start to end: "
            "no place to name; was the microphone muted?"
        )
    if np.any(silent):
        where = ", ".join(map(str, np.flatnonzero(silent)))
        warn(ServantError(f"{path}: windows {where}: silence, no place named"))
    X = audio.featurize(windows)
    usable = usable_rows(X) & ~silent
    if not np.any(usable):
        raise ServantError(
            f"{path}: no window gives features that are finite numbers; "
            "the file is damaged, record it again"
        )
    if not np.all(usable):
        warn(
            ServantError(
                f"{path}: windows {', '.join(map(str, np.flatnonzero(~usable)))}: "
                "features not finite numbers"
            )
        )
    return X[usable], usable


def _predict_pictures(
    args: argparse.Namespace, model: dict[str, Recogniser]
) -> tuple[list[dict[str, Any]], list[str], list[Said]]:
    """The place of each `--image` picture: as JSON rows, as lines, and the opinions (for the
    decision). Confidences are shown as the live engine shows them: beside a sound that knows
    elsewhere, not as shares."""
    visual = _role(model, "visual", args.model)
    X = checked_rows(visual.featurize([read_picture(p) for p in args.image]), "pictures")
    predictions = said_of(visual, X)
    closed_beside_open = beside_open_sound(model.get("acoustic"), visual)
    figures = [
        shown(None if s == UNKNOWN else s, c, visual.confidence_unit, p or {}, closed_beside_open)
        for s, c, p in predictions
    ]
    rows = [
        {"picture": str(p), "scene": s, "confidence": c, "confidence_unit": unit}
        for p, (s, _, _), (c, unit) in zip(args.image, predictions, figures, strict=True)
    ]
    lines = [
        f"Visual {p.name}: {_judged(s, c, unit)}"
        for p, (s, _, _), (c, unit) in zip(args.image, predictions, figures, strict=True)
    ]
    return rows, lines, predictions


def _predict_decision(
    args: argparse.Namespace,
    model: dict[str, Recogniser],
    fusion: FusionNet | None,
    first_acoustic: Said,
    visual_predictions: list[Said],
) -> tuple[dict[str, Any], str]:
    """The decision, as JSON and as a line, through the pipeline the live engine decides with:
    a learned net saved with the model by `train --learned-fusion` (without one, its fallback),
    or a rule policy."""
    config = policy_config(args)
    policy = (
        LearnedFusion(config, fusion) if args.policy == "learned" else POLICIES[args.policy](config)
    )
    open_roles = [r for r in ("acoustic", "visual") if knows_elsewhere(model.get(r))]
    decision = run_encounter(policy, config, first_acoustic, visual_predictions, open_roles)
    shared = decision_unit(model.get("acoustic"), model.get("visual"))
    said = "sure it is here and not elsewhere" if decision.not_elsewhere else "average confidence"
    entry = {
        "scene": decision.scene,
        "line": decision.line,
        "confidence": decision.confidence,
        "confidence_unit": shared,
        "leaned_on": list(decision.leaned_on),
    }
    average = confidence_text(decision.confidence, shared)
    return entry, f"{decision.line} ({said} {average})"


def _judged(scene: str, confidence: float, unit: str | None) -> str:
    """A prediction in words: the scene and its confidence with its unit ("coffee (confidence
    88.0 %)", "street (confidence -6434.0 eq. 1)"); an unknown place has no confidence to show."""
    if scene == UNKNOWN:
        return place(None)
    return f"{scene} (confidence {confidence_text(confidence, unit)})"


def _role(model: dict[str, Recogniser], role: str, path: Path) -> Recogniser:
    if role not in model:
        raise ServantError(
            f"{path}: this model has no {role} recogniser (train it with two scenes or more)"
        )
    return model[role]
