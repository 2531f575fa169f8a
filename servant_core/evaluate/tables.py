"""The paper's Table I (the terminal's line per picture × recording) and Table II (the mean
confidence per cell), computed (`paper_tables`) and printed (`format_tables`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from servant_core.choices import IMAGE_TRAIN_FRACTION
from servant_core.errors import ServantError
from servant_core.evaluate.fusion import run_fusion
from servant_core.evaluate.paired import PairedFit, fit_paired, paired_scenes
from servant_core.evaluate.splits import TRAIN_FRACTION
from servant_core.fusion import FusionConfig
from servant_core.library import Picture, SceneLibrary, iter_recording_windows, read_pictures


def _first_test_items(
    library: SceneLibrary,
    test_library: SceneLibrary | None,
    scenes: Sequence[str],
    rate: int,
    seconds: float,
    on_error: Callable[[ServantError], None] | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, tuple[Picture, np.ndarray]]]:
    """One test window and one test picture (with its pixels) per scene. Without a test library
    they are held out of `library`: a window after the temporal split point, a picture after the
    file-order split. A file that cannot be read goes to `on_error` (which may raise) and the
    next one is taken."""
    windows: dict[str, np.ndarray] = {}
    pictures: dict[str, tuple[Picture, np.ndarray]] = {}
    source = test_library if test_library is not None else library
    for scene in scenes:
        recs = [r for r in source.recordings if r.scene == scene]
        for _, _, w in iter_recording_windows(recs, rate, seconds, on_error):
            index = (
                0
                if test_library is not None
                else min(max(int(math.floor(TRAIN_FRACTION * len(w))), 1), len(w) - 1)
            )
            windows[scene] = w[index : index + 1]
            break  # the first readable recording
        pics = sorted((p for p in source.pictures if p.scene == scene), key=lambda p: p.path.name)
        index = (
            0
            if test_library is not None
            else min(max(int(math.floor(IMAGE_TRAIN_FRACTION * len(pics))), 1), len(pics) - 1)
        )
        for picture in pics[index:]:
            images, kept = read_pictures([picture], on_error)
            if kept:
                pictures[scene] = (picture, images[0])
                break
        if scene not in windows or scene not in pictures:
            raise ServantError(
                f"{source.root}: {scene}: no readable recording or picture left to test on"
            )
    return windows, pictures


def paper_tables(
    library: SceneLibrary,
    test_library: SceneLibrary | None = None,
    acoustic_method: str = "paper",
    visual_method: str = "paper",
    config: FusionConfig | None = None,
    on_error: Callable[[ServantError], None] | None = None,
    on_progress: Callable[[str], Callable[[int, int], None]] | None = None,
) -> dict[str, Any]:
    """The paper's Table I (terminal line per picture × recording) and Table II (average
    confidence per cell, 0.000 where no scene), for every scene with recordings and pictures;
    `on_progress` as `fit_paired`'s."""
    config = config or FusionConfig()
    paired = paired_scenes(library, test_library, "the tables need")
    library = library.restricted(paired)
    fitted = fit_paired(
        library,
        acoustic_method,
        visual_method,
        on_error,
        train_on_all=test_library is not None,
        on_progress=on_progress,
    )
    audio, visual = fitted.audio, fitted.visual

    windows, pictures = _first_test_items(
        library,
        test_library,
        paired,
        audio.rate,
        audio.window_seconds,
        on_error,
    )
    cells = _cells(fitted, paired, windows, pictures, config)
    return {
        "scenes": paired,
        "acoustic_method": acoustic_method,
        "visual_method": visual_method,
        "confidence_units": {"acoustic": audio.confidence_unit, "visual": visual.confidence_unit},
        "pictures": {s: str(p.path) for s, (p, _) in pictures.items()},
        "cells": cells,
    }


def _cells(
    fitted: PairedFit,
    scenes: Sequence[str],
    windows: dict[str, np.ndarray],
    pictures: dict[str, tuple[Picture, np.ndarray]],
    config: FusionConfig,
) -> dict[str, dict[str, dict[str, Any]]]:
    """Each cell of the tables, picture scene by recording scene: what the sequential rule
    decides of that picture and that window, and what each recogniser said."""
    audio, visual = fitted.audio, fitted.visual
    cells: dict[str, dict[str, dict[str, Any]]] = {}
    for picture_scene in scenes:
        Xv = visual.featurize([pictures[picture_scene][1]])
        v = (str(visual.predict(Xv)[0]), float(visual.confidence(Xv)[0]))
        cells[picture_scene] = {}
        for recording_scene in scenes:
            Xa = audio.featurize(windows[recording_scene])
            a = (str(audio.predict(Xa)[0]), float(audio.confidence(Xa)[0]))
            decision = run_fusion("sequential", config, a, [v])
            cells[picture_scene][recording_scene] = {
                "line": decision.line,
                "confidence": decision.confidence,
                "acoustic": {"scene": a[0], "confidence": a[1]},
                "visual": {"scene": v[0], "confidence": v[1]},
            }
    return cells


def format_tables(tables: dict[str, Any]) -> str:
    """Plain-text Table I and Table II: rows are pictures, columns are recordings."""
    scenes = tables["scenes"]
    cells = tables["cells"]
    head = ["picture \\ recording", *scenes]

    def grid(title: str, value: Callable[[dict[str, Any]], str]) -> list[str]:
        rows = [[f"{s} picture", *(value(cells[s][r]) for r in scenes)] for s in scenes]
        widths = [max(len(str(x)) for x in col) for col in zip(head, *rows, strict=True)]
        fmt = "  ".join(f"{{:<{w}}}" for w in widths)
        return [title, fmt.format(*head), *(fmt.format(*row) for row in rows)]

    lines = [_tables_header(tables), ""]
    lines += grid("Table I: terminal output", lambda c: c["line"])
    lines.append("")
    units = list(tables.get("confidence_units", {}).values())
    unit = "%" if set(units) == {"%"} else f"mean of {' and '.join(map(str, units))}"
    title = f"Table II: average confidence ({unit})" if units else "Table II: average confidence"
    lines += grid(title, lambda c: f"{c['confidence']:.3f}")
    return "\n".join(lines)


def _tables_header(tables: dict[str, Any]) -> str:
    """What the tables are of: the methods, and the unit of their confidences."""
    audio, image = tables["acoustic_method"], tables["visual_method"]
    units = tables.get("confidence_units", {})
    if (audio, image) == ("paper", "paper"):
        return (
            "The paper's method (its Tables I and II): sound by K-Means on FFT windows, pictures "
            "by dominant colours, decided by its sequential 30 s / 20 s rule. Confidences are "
            "the mean of its eq. 1 (sound: 100 - distance / 10000) and eq. 2 (pictures: 100 - "
            "distance), not percentages: far below zero is usual."
        )
    said = ", ".join(f"{sense} {unit}" for sense, unit in units.items()) or "not said"
    return (
        f"Tables I and II as the paper's, with sound by `{audio}` and pictures by `{image}`, "
        f"decided by the paper's sequential rule; confidences: {said}."
    )
