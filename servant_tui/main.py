"""The `servant` console script: the TUI, or a headless subcommand of servant_core.cli.

`servant` alone opens the TUI on the live devices; `servant demo` opens it on the demo scenes
(`servant demo --headless`, where the engine offers it, stays on the command line). Every other
subcommand is servant_core's.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from servant_core.cli import build_parser as build_core_parser
from servant_core.cli import run_handler
from servant_core.errors import ServantError


def _subparsers(parser: argparse.ArgumentParser) -> argparse._SubParsersAction:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action
    raise RuntimeError("servant_core.cli.build_parser() has no subcommands")


def build_parser() -> argparse.ArgumentParser:
    parser = build_core_parser()
    subparsers = _subparsers(parser)
    if "demo" not in subparsers.choices:
        demo = subparsers.add_parser(
            "demo", help="open the terminal application on the demo scenes"
        )
        demo.add_argument("--seed", type=int, default=0, help="seed of the demo scenes")
    return parser


def run_tui(demo: bool, seed: int = 0) -> int:
    from servant_tui.app import ServantApp

    try:
        if demo:
            from servant_core.engine import build_demo_engine

            app = ServantApp(build_demo_engine(seed=seed), mode="demo")
        else:
            from servant_core.engine import build_live_engine
            from servant_core.settings import load_settings

            settings = load_settings()
            app = ServantApp(build_live_engine(settings), mode="live", settings=settings)
    except ServantError as error:
        print(f"servant: error: {error}", file=sys.stderr)
        return 2
    app.run()
    return app.return_code or 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.command is None:
        return run_tui(demo=False)
    if args.command == "demo" and not getattr(args, "headless", False):
        return run_tui(demo=True, seed=getattr(args, "seed", 0))
    return run_handler(args)


if __name__ == "__main__":
    sys.exit(main())
