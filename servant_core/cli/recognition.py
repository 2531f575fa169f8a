"""`servant train | predict | eval | table`: the paper's recognition pipeline, headless; what
its commands share (reading a library, what a file that cannot be read does, the options'
windows).

The options are registered by `servant_core.cli.recognition_options`, which loads no library;
each command's module is imported when it runs: `train`, `predict`, `evaluation` (`eval` and
`table`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from servant_core.cli import one_line
from servant_core.errors import ServantError
from servant_core.fusion import FusionConfig
from servant_core.library import SceneLibrary


def policy_config(args: argparse.Namespace) -> FusionConfig:
    return FusionConfig(args.acoustic_window, args.confirm_window, args.pictures)


def warn(error: ServantError) -> None:
    print(f"servant: warning: skipped {one_line(str(error))}", file=sys.stderr)


def _stop(error: ServantError) -> None:
    raise ServantError(f"{error}; or add --skip-bad to leave such files out, each with a warning")


def on_bad_file(args: argparse.Namespace) -> Callable[[ServantError], None]:
    """What every command that reads a library does with a file it cannot read: stop, naming the
    file and `--skip-bad` (a model or a figure quietly made without it may mislead), or with
    `--skip-bad` leave it out, warning."""
    return warn if args.skip_bad else _stop


def scene_library(root: Path, scenes: str | None) -> SceneLibrary:
    library = SceneLibrary.scan(root)
    return (
        library.restricted([s.strip() for s in scenes.split(",") if s.strip()])
        if scenes
        else library
    )


def audio_params(args: argparse.Namespace) -> dict[str, Any]:
    # Each method has its own rate (codebook works at 22,050 Hz, below every recording's band).
    rate = {} if args.rate is None else {"rate": args.rate}
    return {**rate, "window_seconds": args.window}
