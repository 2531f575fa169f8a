"""`servant train | predict | eval | table`: the paper's recognition pipeline, headless.

Their options are registered by `servant_core.cli.recognition_options`, which loads no library;
this module is imported when one of the commands runs."""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import numpy as np

from servant_core.audio import SILENT_DBFS, cut_windows, is_silent, read_audio
from servant_core.cli import emit, one_line
from servant_core.engine import FRESH_METHODS, decision_unit
from servant_core.engine.learning import library_fusion_net, refit_samples
from servant_core.errors import ServantError
from servant_core.evaluate import (
    Said,
    evaluate_audio,
    evaluate_fusion,
    evaluate_image,
    format_tables,
    paper_tables,
    read_groups,
    recording_groups,
    run_encounter,
    said_of,
)
from servant_core.event_text import confidence_text, place
from servant_core.features.rows import checked_rows, usable_rows
from servant_core.fusion import POLICIES, FusionConfig, FusionNet, LearnedFusion
from servant_core.fusion.elsewhere import beside_open_sound, shown
from servant_core.library import (
    SceneLibrary,
    featurize_recordings,
    read_picture,
    read_pictures,
    visits_of,
)
from servant_core.modelfile import check_model_output, load_model_and_fusion, replace_model
from servant_core.place_names import printable_name
from servant_core.progress import Progress
from servant_core.recognisers import (
    UNKNOWN,
    AcousticRecogniser,
    Recogniser,
    make_audio_recogniser,
    make_recogniser,
)
from servant_core.recognisers.background import kept_out
from servant_core.recognisers.base import (
    fit_visits,
    knows_elsewhere,
    open_predict,
    open_probabilities,
)
from servant_core.senses import ROLE_SENSE, SAMPLE_SENSES
from servant_core.storage import default_model_file, file_stamp


def _fusion_config(args: argparse.Namespace) -> FusionConfig:
    return FusionConfig(args.acoustic_window, args.confirm_window, args.pictures)


def _warn(error: ServantError) -> None:
    print(f"servant: warning: skipped {one_line(str(error))}", file=sys.stderr)


def _stop(error: ServantError) -> None:
    raise ServantError(f"{error}; or add --skip-bad to leave such files out, each with a warning")


def _on_bad_file(args: argparse.Namespace) -> Callable[[ServantError], None]:
    """What every command that reads a library does with a file it cannot read: stop, naming the
    file and `--skip-bad` (a model or a figure quietly made without it may mislead), or with
    `--skip-bad` leave it out, warning."""
    return _warn if args.skip_bad else _stop


def _library(root: Path, scenes: str | None) -> SceneLibrary:
    library = SceneLibrary.scan(root)
    return (
        library.restricted([s.strip() for s in scenes.split(",") if s.strip()])
        if scenes
        else library
    )


def _audio_params(args: argparse.Namespace) -> dict[str, Any]:
    # Each method has its own rate (codebook works at 22,050 Hz, below every recording's band).
    rate = {} if args.rate is None else {"rate": args.rate}
    return {**rate, "window_seconds": args.window}


def cmd_train(args: argparse.Namespace) -> int:
    """`servant train`: fit a recogniser per sense the library has two places or more for (and
    with `--learned-fusion` the net over them), write the model, and say what was trained."""
    output = _train_output(args)
    stamp = file_stamp(output)
    library = SceneLibrary.scan(args.root)
    on_error = _on_bad_file(args)
    recognisers, trained = _train_recognisers(args, library, on_error)
    if not recognisers:
        raise ServantError(
            f"{args.root}: training needs at least two scene folders with recordings, pictures "
            "or sensor logs"
        )
    summary: dict[str, Any] = {"root": str(args.root), **trained}
    fusion = None
    if args.learned_fusion:
        fusion, summary["fusion"] = _train_fusion(args, library, recognisers, on_error)
    # the model `servant` loads is kept when replaced; a file named with -o is the user's say
    backup = replace_model(output, recognisers, fusion, stamp, backup=args.output is None)
    summary["model"] = str(output)
    summary["backup"] = None if backup is None else str(backup)
    emit(args, summary, "\n".join(_trained_lines(summary, output, backup)))
    return 0


def _train_output(args: argparse.Namespace) -> Path:
    """The file `train` writes, checked before any work: the model `servant` loads is replaced
    only with `--force`."""
    output = check_model_output(args.output or default_model_file())
    if args.output is None and output.exists() and not args.force:
        raise ServantError(
            f"{output}: holds the model `servant` loads (what teach mode and earlier trainings "
            "taught); not replaced. Give -o FILE to train into another file, or --force to "
            "replace it (the old one is kept beside it as a numbered backup)"
        )
    return output


def _train_recognisers(
    args: argparse.Namespace, library: SceneLibrary, on_error: Callable[[ServantError], None]
) -> tuple[dict[str, Recogniser], dict[str, Any]]:
    """Each recogniser the library has two places or more for, by role, and the summary's
    entries: `warnings` (the labels' warnings of sound and pictures), then one per role."""
    recognisers: dict[str, Recogniser] = {}
    summary: dict[str, Any] = {"warnings": []}
    if len({r.scene for r in library.recordings}) >= 2:
        recognisers["acoustic"], summary["acoustic"] = _train_audio(args, library, on_error)
        summary["warnings"] += _label_warnings(recognisers["acoustic"])
    if len({p.scene for p in library.pictures}) >= 2:
        recognisers["visual"], summary["visual"] = _train_visual(args, library, on_error)
        summary["warnings"] += _label_warnings(recognisers["visual"])
    for sense, model in _train_samples(args, library, on_error).items():
        recognisers[sense] = model
        summary[sense] = {"method": model.method, "scenes": model.scenes_}
    return recognisers, summary


def _label_warnings(model: Recogniser) -> list[str]:
    """What a recogniser's labels warned of while it was fitted (none if it keeps no labels)."""
    warnings: list[str] = getattr(getattr(model, "labels_", None), "warnings", list)()
    return warnings


def _train_audio(
    args: argparse.Namespace, library: SceneLibrary, on_error: Callable[[ServantError], None]
) -> tuple[Recogniser, dict[str, Any]]:
    """The sound recogniser fitted on every recording's windows, and its summary entry."""
    audio = kept_out(
        make_audio_recogniser(args.audio_method, **_audio_params(args)), library.recordings
    )
    wf = featurize_recordings(
        library.recordings,
        audio.featurize,
        audio.rate,
        args.window,
        on_error,
        Progress("listening to recordings"),
    )
    fit_visits(audio, wf.features, wf.scenes, visits_of(wf))
    return audio, {
        "method": args.audio_method,
        "scenes": audio.scenes_,
        "n_windows": len(wf.scenes),
    }


def _train_visual(
    args: argparse.Namespace, library: SceneLibrary, on_error: Callable[[ServantError], None]
) -> tuple[Recogniser, dict[str, Any]]:
    """The picture recogniser fitted on every picture that reads, and its summary entry."""
    visual = make_recogniser("image", args.image_method)
    images, kept = read_pictures(library.pictures, on_error, Progress("reading pictures"))
    X_pictures = visual.featurize(images)
    visual.fit(X_pictures, [p.scene for p in kept])
    return visual, {"method": args.image_method, "scenes": visual.scenes_, "n_pictures": len(kept)}


def _train_samples(
    args: argparse.Namespace, library: SceneLibrary, on_error: Callable[[ServantError], None]
) -> dict[str, Recogniser]:
    """A recogniser per sensor sense whose logs cover two places or more. With `--skip-bad`, a
    sense that cannot be trained is left out with a warning; without, its error stops training."""
    models: dict[str, Recogniser] = {}
    for sense, files in library.samples.items():
        if len({f.scene for f in files}) < 2:
            continue
        stream = SAMPLE_SENSES[sense].stream
        try:
            model = refit_samples(
                files,
                stream or sense,
                make_recogniser(sense, FRESH_METHODS[sense]),
                args.window,
                on_error,
                Progress(f"reading {sense} logs"),
            )
        except ServantError as error:
            if not args.skip_bad:
                raise
            # e.g. the bad log was a scene's only one: this sense is left out, the others train
            on_error(ServantError(f"{sense}: not trained: {error}"))
            model = None
        if model is not None:
            models[sense] = model
    return models


def _train_fusion(
    args: argparse.Namespace,
    library: SceneLibrary,
    recognisers: dict[str, Recogniser],
    on_error: Callable[[ServantError], None],
) -> tuple[FusionNet | None, dict[str, Any]]:
    """`--learned-fusion`: the net over the trained senses (None when too little was taught),
    and its summary entry (its senses, places and threshold, or why the parallel policy decides)."""
    by_sense = {ROLE_SENSE[role]: model for role, model in recognisers.items()}
    fusion, reason = library_fusion_net(library, by_sense, args.window, on_error)
    entry = (
        {"senses": fusion.senses_, "scenes": fusion.scenes_, "threshold": fusion.threshold_}
        if fusion is not None
        else {"fallback": reason}
    )
    return fusion, entry


def _trained_lines(summary: dict[str, Any], output: Path, backup: Path | None) -> list[str]:
    """`train`'s plain text: where the model went, a line per trained sense, the learned
    fusion's line when asked for, then the warnings."""
    lines = [f"model written to {output}"]
    if backup is not None:
        lines[0] += f"; the model it replaced is kept as {backup}"
    for role in ("acoustic", "visual", *SAMPLE_SENSES):
        if role in SAMPLE_SENSES and role in summary:
            s = summary[role]
            lines.append(f"{role}: {s['method']} on its logs, scenes {_names(s['scenes'])}")
        elif role in summary:
            s = summary[role]
            count = s.get("n_windows", s.get("n_pictures"))
            unit = "windows" if "n_windows" in s else "pictures"
            lines.append(f"{role}: {s['method']} on {count} {unit}, scenes {_names(s['scenes'])}")
    if "fusion" in summary:
        f = summary["fusion"]
        lines.append(
            f"learned fusion: over {', '.join(f['senses'])}, threshold {f['threshold']:.3f}"
            if "threshold" in f
            else f"learned fusion: none, the parallel policy decides ({f['fallback']})"
        )
    lines += [f"warning: {w}" for w in summary["warnings"]]
    return lines


def _names(scenes: list[str]) -> str:
    """Places as one line, a folder's name holding a newline or an escape shown escaped."""
    return ", ".join(printable_name(scene) for scene in scenes)


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
        _warn(ServantError(f"{path}: windows {where}: silence, no place named"))
    X = audio.featurize(windows)
    usable = usable_rows(X) & ~silent
    if not np.any(usable):
        raise ServantError(
            f"{path}: no window gives features that are finite numbers; "
            "the file is damaged, record it again"
        )
    if not np.all(usable):
        _warn(
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
    config = _fusion_config(args)
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


def _figure(result: dict[str, Any], key: str) -> str:
    """`0.912`, or over seeds `0.912 (std 0.004, 0.905-0.918)`."""
    text = f"{result[key]:.3f}"
    spread = result.get("spread", {}).get(key)
    if spread:
        text += f" (std {spread['std']:.3f}, {spread['min']:.3f}-{spread['max']:.3f})"
    return text


def _format_scores(result: dict[str, Any]) -> str:
    seeds = f" seeds={result['seeds']}" if "seeds" in result else ""
    lines = [
        f"{result['sense']} method={result['method']} protocol={result['protocol']} "
        f"n_test={result['n_test']}{seeds}",
        f"accuracy           {_figure(result, 'accuracy')}",
        f"balanced accuracy  {_figure(result, 'balanced_accuracy')}",
        f"log loss           {_figure(result, 'log_loss')}",
        f"unknown rate       {_figure(result, 'unknown_rate')}",
        "recall per scene:",
    ]
    lines += [f"  {scene:<14} {recall:.3f}" for scene, recall in result["per_class"].items()]
    if "per_recording" in result:
        lines.append("recall per recording (heard as):")
        lines += [
            f"  {name:<40} {r['recall']:.3f}  "
            + ", ".join(f"{scene} {n}" for scene, n in r["heard_as"].items())
            for name, r in result["per_recording"].items()
        ]
    if "folds" in result:
        lines.append("left out in turn (recordings, test windows, scenes it alone has):")
        lines += [
            f"  {f['left_out']:<24} {len(f['recordings']):>3} {f['n_test']:>5}  "
            + (", ".join(f["unseen_scenes"]) or "-")
            for f in result["folds"]
        ]
    lines += [f"skipped fold: {s}" for s in result.get("skipped_folds", [])]
    return "\n".join(lines)


def _format_fewshot(result: dict[str, Any]) -> str:
    """One line per number of shots."""
    lines = [f"audio method={result['method']} protocol=fewshot"]
    lines += [
        f"k={row['shots']:<3} n_train={row['n_train']:<4} n_test={row['n_test']:<4} "
        f"balanced accuracy {_figure(row, 'balanced_accuracy')}  log loss {row['log_loss']:.3f}"
        for row in result["rows"]
    ]
    return "\n".join(lines)


def cmd_eval_audio(args: argparse.Namespace) -> int:
    if args.test is not None and args.protocol != "temporal":
        raise ServantError(
            "--test trains on all of ROOT and tests on all of TEST; leave out --protocol"
        )
    if args.groups is not None and args.protocol != "source":
        raise ServantError(
            "--groups names the groups of --protocol source; add it or leave out --groups"
        )
    library = _with_recordings(_library(args.root, args.scenes), args.min_recordings)
    groups = read_groups(args.groups, library.root) if args.groups is not None else None
    if args.protocol == "recording":
        _check_recording_protocol(library)
    if args.protocol == "source":
        _check_source_protocol(library, recording_groups(library, groups))
    test = _library(args.test, args.scenes) if args.test else None
    result = evaluate_audio(
        library,
        args.method,
        args.protocol,
        _audio_params(args),
        _on_bad_file(args),
        Progress("listening to recordings"),
        test_library=test,
        shots=args.shots,
        seeds=args.seeds,
        groups=groups,
        on_fold=Progress("training and testing, a model a fold"),
    )
    text = _format_fewshot(result) if "rows" in result else _format_scores(result)
    emit(args, result, text)
    return 0


def _check_recording_protocol(library: SceneLibrary) -> None:
    """Leaving a recording out must leave two scenes to train on, for at least one recording."""
    per_scene = Counter(r.scene for r in library.recordings)
    if len(per_scene) < 2 or (len(per_scene) == 2 and max(per_scene.values()) < 2):
        found = ", ".join(f"{scene} {n}" for scene, n in sorted(per_scene.items())) or "none"
        raise ServantError(
            f"{library.root}: nothing to evaluate: the recording protocol trains without the "
            "recording it tests, which leaves fewer than two scenes here (recordings per scene: "
            f"{found}); add a second recording to a scene, a third scene, or use --protocol "
            "temporal"
        )


def _with_recordings(library: SceneLibrary, least: int) -> SceneLibrary:
    """`--min-recordings`: the scenes with at least `least` recordings."""
    if least <= 1:
        return library
    per_scene = Counter(r.scene for r in library.recordings)
    keep = [s for s in library.scenes if per_scene[s] >= least]
    if not keep:
        raise ServantError(
            f"{library.root}: no scene has {least} recordings or more (the most: "
            f"{max(per_scene.values(), default=0)}); lower --min-recordings"
        )
    return library.restricted(keep)


def _check_source_protocol(library: SceneLibrary, groups: list[str]) -> None:
    """Leaving a group out must leave two scenes to train on, for at least one group."""
    scenes_of: dict[str, set[str]] = {}
    for recording, group in zip(library.recordings, groups, strict=True):
        scenes_of.setdefault(group, set()).add(recording.scene)
    everything = {r.scene for r in library.recordings}
    if not any(
        len({s for g, scenes in scenes_of.items() if g != left_out for s in scenes}) >= 2
        for left_out in scenes_of
    ):
        raise ServantError(
            f"{library.root}: nothing to evaluate: the source protocol trains without the source "
            f"it tests, which leaves fewer than two scenes here ({len(scenes_of)} source(s), "
            f"scenes {', '.join(sorted(everything)) or 'none'}); add recordings from other "
            "sources, or use --protocol recording"
        )


def cmd_eval_image(args: argparse.Namespace) -> int:
    test = _library(args.test, args.scenes) if args.test else None
    result = evaluate_image(
        _library(args.root, args.scenes),
        test,
        args.method,
        args.split,
        on_error=_on_bad_file(args),
        seeds=args.seeds,
    )
    emit(args, result, _format_scores(result))
    return 0


def cmd_eval_fusion(args: argparse.Namespace) -> int:
    result = evaluate_fusion(
        _library(args.root, args.scenes),
        args.audio_method,
        args.image_method,
        args.policy,
        _fusion_config(args),
        _on_bad_file(args),
        drop_sense=args.drop_sense,
        seeds=args.seeds,
    )
    dropped = f" without {result['drop_sense']}" if result["drop_sense"] else ""
    lines = [
        f"fusion policy={result['policy']} methods={result['method']} "
        f"scenes={','.join(result['scenes'])}{dropped}",
        f"windows {result['n_test']}  decided {_figure(result, 'decision_rate')}  "
        f"right when decided {_figure(result, 'precision')}  "
        f"accuracy {_figure(result, 'accuracy')}",
    ]
    if result["policy"] == "learned":
        lines += [
            f"seed {r['random_state']}: threshold {r['threshold']}, fell back: {r['fallback']}"
            if r["fallback"]
            else f"seed {r['random_state']}: threshold {r['threshold']:.3f}, leaned on "
            + ", ".join(f"{k} {n}" for k, n in r["leaned_on"].items())
            for r in result.get("per_seed", [result])
        ]
    emit(args, result, "\n".join(lines))
    return 0


def cmd_table(args: argparse.Namespace) -> int:
    test = _library(args.test, args.scenes) if args.test else None
    tables = paper_tables(
        _library(args.library, args.scenes),
        test,
        args.audio_method,
        args.image_method,
        on_error=_on_bad_file(args),
        on_progress=Progress,
    )
    emit(args, tables, format_tables(tables))
    return 0
