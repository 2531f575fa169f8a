"""The universal background: many places that are not the wearer's, shipped with Servant.

A taught place is scored against this background (as in GMM-UBM speaker verification), so that the
arm acts on the probability of *here and not somewhere else*. `background_audio.npz` (beside this
module, written by `scripts/fit-background`, read by `load_background`) holds level-free log-mel
windows quantised to bytes, each with its recording's name: a recording taught or tested on is
left out (`exclude`). Recognisers describe its frames through their own codebooks.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

BACKGROUND_PATH = Path(__file__).with_name("background_audio.npz")
# The featurizer parameters the stored frames were made with; a model with others cannot use them.
FRAME_KEYS = ("rate", "window_seconds", "n_mels", "frame_seconds", "fmin", "fmax")
ELSEWHERE = "<elsewhere>"


@dataclass
class Background:
    """Log-mel frames (n, frames, bands) float32 and each window's recording name (n,)."""

    frames: np.ndarray
    recordings: np.ndarray


def quantised(frames: np.ndarray) -> tuple[np.ndarray, float, float]:
    """(uint8 codes, low, step): frames rounded onto 256 levels between their 0.01 % and
    99.99 % quantiles (pure)."""
    low, high = (float(v) for v in np.quantile(frames, [1e-4, 1 - 1e-4]))
    step = max(high - low, 1e-6) / 255.0
    codes = np.clip(np.rint((frames - low) / step), 0, 255).astype(np.uint8)
    return codes, low, step


def save_background(
    path: Path,
    frames: np.ndarray,
    recordings: list[str],
    params: dict[str, Any],
    keys: Sequence[str] = FRAME_KEYS,
) -> None:
    """Write featurized background windows (`frames`, any shape a window) and their recordings'
    names; `keys`: the featurizer parameters (of `params`) a model must share to use them."""
    codes, low, step = quantised(frames)
    header = {"params": {k: params[k] for k in keys}, "low": low, "step": step}
    np.savez_compressed(
        path,
        header=np.array(json.dumps(header)),
        codes=codes,
        recordings=np.asarray(recordings, dtype=str),
    )


def load_background(
    params: dict[str, Any], exclude: Sequence[str] = (), path: Path | None = None
) -> Background | None:
    """The background frames for a featurizer with `params`, without the windows of recordings
    named in `exclude` (file names, compared without their folders); None when there is no
    background file or its frames were made with other featurizer parameters (those the file
    names)."""
    path = BACKGROUND_PATH if path is None else path
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as data:
        header = json.loads(str(data["header"]))
        if any(params.get(k) != v for k, v in header["params"].items()):
            return None
        codes, recordings = data["codes"], data["recordings"].astype(str)
    excluded = {Path(name).name for name in exclude}
    keep = np.array([Path(r).name not in excluded for r in recordings], dtype=bool)
    frames = (codes[keep].astype(np.float32) * np.float32(header["step"])) + np.float32(
        header["low"]
    )
    return Background(frames, recordings[keep])


def kept_out(model: Any, recordings: Sequence[Any]) -> Any:
    """`model`, told to keep the windows of `recordings` (library `Recording`s or paths) out of
    its background, where it declares one (`background_path`): a recording taught, or tested on,
    is not somewhere else."""
    if model.background_path is not None:
        names = {Path(getattr(r, "path", r)).name for r in recordings}
        model.background_exclude = tuple(sorted(names))
    return model
