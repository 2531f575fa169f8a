"""The headless command line: `servant <subcommand>`; plain text by default, JSON with `--json`.

Each module listed in SUBCOMMAND_MODULES owns some subcommands and has
`register(subparsers) -> None`, which adds them with `set_defaults(handler=function)`;
a handler takes the parsed arguments and returns the exit status.
The TUI entry point (`servant_tui.main`) builds on this parser; this package never imports Textual.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from collections.abc import Sequence
from typing import Any

from servant_core.errors import ServantError

SUBCOMMAND_MODULES = (
    "servant_core.cli.recognition",
    "servant_core.cli.arm",
    "servant_core.cli.live",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="servant",
        description="Scene recognition from sound and colour, driving a wearable arm. "
        "With no subcommand, opens the terminal application on the live devices.",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMAND_MODULES:
        importlib.import_module(name).register(subparsers)
    return parser


def emit(args: argparse.Namespace, payload: Any, text: str) -> None:
    """Print `payload` as JSON when `--json` was given, else the plain `text`."""
    if getattr(args, "json", False):
        print(json.dumps(payload, indent=2, default=_json_default))
    else:
        print(text)


def _json_default(value: Any) -> Any:
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def run_handler(args: argparse.Namespace) -> int:
    """Run a parsed subcommand; a ServantError becomes one line on stderr and exit status 2."""
    try:
        return int(args.handler(args) or 0)
    except ServantError as error:
        print(f"servant: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return 0
    return run_handler(args)
