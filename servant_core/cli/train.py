"""`servant train`: a recogniser per sense a library has two places or more for (and the
learned fusion's net over them), written to a model file."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from servant_core.cli import emit
from servant_core.cli.recognition import audio_params, on_bad_file
from servant_core.engine import FRESH_METHODS
from servant_core.engine.learning import library_fusion_net, refit_samples
from servant_core.errors import ServantError
from servant_core.fusion import FusionNet
from servant_core.library import SceneLibrary, featurize_recordings, read_pictures, visits_of
from servant_core.modelfile import check_model_output, replace_model
from servant_core.place_names import printable_name
from servant_core.progress import Progress
from servant_core.recognisers import Recogniser, make_audio_recogniser, make_recogniser
from servant_core.recognisers.background import kept_out
from servant_core.recognisers.base import fit_visits
from servant_core.senses import ROLE_SENSE, SAMPLE_SENSES
from servant_core.storage import default_model_file, file_stamp


def cmd_train(args: argparse.Namespace) -> int:
    """`servant train`: fit a recogniser per sense the library has two places or more for (and
    with `--learned-fusion` the net over them), write the model, and say what was trained."""
    output = _train_output(args)
    stamp = file_stamp(output)
    library = SceneLibrary.scan(args.root)
    on_error = on_bad_file(args)
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
    """The file `train` writes, checked before any work: its folder can be written, and the model
    `servant` loads is replaced only with `--force`."""
    output = check_model_output(args.output or default_model_file())  # its folder too
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
        summary["warnings"] += recognisers["acoustic"].fit_warnings()
    if len({p.scene for p in library.pictures}) >= 2:
        recognisers["visual"], summary["visual"] = _train_visual(args, library, on_error)
        summary["warnings"] += recognisers["visual"].fit_warnings()
    for sense, model in _train_samples(args, library, on_error).items():
        recognisers[sense] = model
        summary[sense] = {"method": model.method, "scenes": model.scenes_}
    return recognisers, summary


def _train_audio(
    args: argparse.Namespace, library: SceneLibrary, on_error: Callable[[ServantError], None]
) -> tuple[Recogniser, dict[str, Any]]:
    """The sound recogniser fitted on every recording's windows, and its summary entry."""
    audio = kept_out(
        make_audio_recogniser(args.audio_method, **audio_params(args)), library.recordings
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
