"""`servant eval audio | image | fusion` and `servant table`: the paper's figures on a library."""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path
from typing import Any

from servant_core.cli import emit
from servant_core.cli.recognition import audio_params, on_bad_file, policy_config, scene_library
from servant_core.errors import ServantError
from servant_core.evaluate import (
    evaluate_audio,
    evaluate_fusion,
    evaluate_image,
    format_tables,
    paper_tables,
    read_groups,
    recording_groups,
)
from servant_core.library import SceneLibrary
from servant_core.progress import Progress


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
    library = _with_recordings(scene_library(args.root, args.scenes), args.min_recordings)
    groups = read_groups(args.groups, library.root) if args.groups is not None else None
    if args.protocol == "recording":
        _check_recording_protocol(library)
    if args.protocol == "source":
        _check_source_protocol(library, recording_groups(library, groups))
    test = scene_library(args.test, args.scenes) if args.test else None
    result = evaluate_audio(
        library,
        args.method,
        args.protocol,
        audio_params(args),
        on_bad_file(args),
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
    result = evaluate_image(
        *_train_and_test(args, args.root),
        args.method,
        args.split,
        on_error=on_bad_file(args),
        seeds=args.seeds,
    )
    emit(args, result, _format_scores(result))
    return 0


def cmd_eval_fusion(args: argparse.Namespace) -> int:
    result = evaluate_fusion(
        scene_library(args.root, args.scenes),
        args.audio_method,
        args.image_method,
        args.policy,
        policy_config(args),
        on_bad_file(args),
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
    tables = paper_tables(
        *_train_and_test(args, args.library),
        args.audio_method,
        args.image_method,
        on_error=on_bad_file(args),
        on_progress=Progress,
    )
    emit(args, tables, format_tables(tables))
    return 0


def _train_and_test(
    args: argparse.Namespace, root: Path
) -> tuple[SceneLibrary, SceneLibrary | None]:
    """The library `root` and the one of `--test` (None without), each of `--scenes` alone."""
    test = scene_library(args.test, args.scenes) if args.test else None
    return scene_library(root, args.scenes), test
