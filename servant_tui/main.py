"""The `servant` console script: the TUI, or a headless subcommand of servant_core.cli."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from servant_core.cli import build_parser, run_handler


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return 0
    return run_handler(args)


if __name__ == "__main__":
    sys.exit(main())
