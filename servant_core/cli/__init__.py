"""The headless command line: `servant <subcommand>`; plain text by default, JSON with `--json`.

Each module named in SUBCOMMANDS owns some subcommands and has `register(subparsers) -> None`,
which adds their options with `set_defaults(handler=function)`; a handler takes the parsed
arguments and returns the exit status. A module is imported only when one of its commands is
parsed: `servant --help` and a light command load none of the heavy libraries the others need.
The TUI entry point (`servant_tui.main`) builds on this parser; this package never imports Textual.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import importlib
import json
import os
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from servant_core.errors import ServantError

RECOGNITION, ARM, LIVE, SENSORS = (
    f"servant_core.cli.{name}" for name in ("recognition_options", "arm", "live", "sensors")
)
# Each command: the module that registers its options, and its line in `servant --help`.
SUBCOMMANDS = {
    "train": (RECOGNITION, "train the recognisers on a scene library"),
    "predict": (RECOGNITION, "recognise a recording and/or pictures with a model"),
    "eval": (RECOGNITION, "evaluate a method on a scene library"),
    "table": (RECOGNITION, "the paper's Table I and Table II for a library"),
    "teach": (ARM, "teach the arm a pose per scene, then ask it (the paper's Fig. 6 session)"),
    "servo": (ARM, "drive or query the arm's servo controller"),
    "emulate-servo": (
        ARM,
        "run a servo controller emulator on a pseudo-terminal (prints the port)",
    ),
    "run": (LIVE, "recognise scenes from the live microphone and camera, and move the arm"),
    "demo": (LIVE, "the built-in demo scenes (no microphone, camera or arm needed)"),
    "emulate-sensors": (
        SENSORS,
        "run a motion and ambient sensor board emulator on a pseudo-terminal (prints the port)",
    ),
}


# Options people reach for on the wrong subcommand, and where they are.
OPTION_HINTS = {
    "--method": "train, eval fusion and table take --audio-method and --image-method",
    "--audio-method": "eval audio and eval image take --method",
    "--image-method": "eval audio and eval image take --method",
}


class DefaultsFormatter(argparse.HelpFormatter):
    """Shows an option's default after its help, unless there is none to show (None, a flag's
    False) or the help already says it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        # by identity: a default of 0 equals False and 0.0 equals it too, yet says something
        shown = not (default is None or default is False or default is argparse.SUPPRESS)
        shown = shown and default != []
        if shown and "default" not in text and action.option_strings:
            text += " (default: %(default)s)"
        return text


class ServantParser(argparse.ArgumentParser):
    """Every (sub)command's `--help` shows the defaults; a misplaced option gets a hint.

    A command's parser starts empty and is filled by its module's `register` the first time it
    parses (`fill`), or at once with `build_parser(lazy=False)`."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", DefaultsFormatter)
        self.filled_by: Callable[[], None] | None = kwargs.pop("filled_by", None)
        super().__init__(*args, **kwargs)

    def fill(self) -> None:
        filled_by, self.filled_by = self.filled_by, None
        if filled_by is not None:
            filled_by()

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        """An option no (sub)command knows is refused by the subcommand it was typed after, so
        that its line points to that command's `--help` (argparse leaves it to `servant`)."""
        self.fill()
        parsed, extras = super().parse_known_args(args, namespace)
        if extras and self._subcommand_of(parsed) is not self:
            self._subcommand_of(parsed).error(f"unrecognized arguments: {' '.join(extras)}")
        return parsed, extras

    def _subcommand_of(self, parsed: argparse.Namespace) -> argparse.ArgumentParser:
        """The innermost (sub)command parser that `parsed` went through (`servant eval audio`)."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                chosen = action.choices.get(getattr(parsed, action.dest, None) or "")
                if isinstance(chosen, ServantParser):
                    return chosen._subcommand_of(parsed)
        return self

    def error(self, message: str) -> Any:
        """One line, as for every other error (argparse would print the usage first)."""
        hints: list[str] = []
        if message.startswith("unrecognized arguments"):
            words = [w.split("=")[0] for w in message.split(":", 1)[-1].split()]
            hints = [OPTION_HINTS[w] for w in words if w in OPTION_HINTS]
        hints.append(f"see `{self.prog} --help`")
        command = self.prog.removeprefix("servant").strip()
        where = f"{command}: " if command else ""
        text = "; ".join([message, *dict.fromkeys(hints)])
        self.exit(2, f"servant: error: {where}{one_line(text)}\n")


class _Listed:
    """What a module's `register` is handed as `subparsers`: `add_parser(name, ...)` returns the
    command's parser already listed (help from SUBCOMMANDS), with its description set."""

    def __init__(self, listed: dict[str, ServantParser]) -> None:
        self.listed = listed

    def add_parser(self, name: str, **kwargs: Any) -> ServantParser:
        parser = self.listed[name]
        if "description" in kwargs:
            parser.description = kwargs["description"]
        return parser


def build_parser(lazy: bool = True) -> argparse.ArgumentParser:
    """The `servant` parser; each command's options are registered when it is first parsed
    (`lazy`), or all at once (for a test that walks every option)."""
    parser = ServantParser(
        prog="servant",
        description="Scene recognition from sound and colour, driving a wearable arm. "
        "With no subcommand, opens the terminal application on the live devices.",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    listed: dict[str, ServantParser] = {}
    registered: set[str] = set()

    def register(module: str) -> None:
        if module not in registered:
            registered.add(module)
            importlib.import_module(module).register(_Listed(listed))
            for name, (owner, _) in SUBCOMMANDS.items():
                if owner == module:
                    listed[name].filled_by = None

    for name, (module, help_line) in SUBCOMMANDS.items():
        listed[name] = subparsers.add_parser(
            name, help=help_line, filled_by=functools.partial(register, module)
        )
    if not lazy:
        for command in listed.values():
            command.fill()
    return parser


def later(module: str, name: str) -> Callable[[argparse.Namespace], int]:
    """The handler `name` of `module`, imported when the command runs: a command's options and
    its `--help` need none of the libraries its work loads."""

    def handler(args: argparse.Namespace) -> int:
        run: Callable[[argparse.Namespace], int] = getattr(importlib.import_module(module), name)
        return run(args)

    handler.__name__ = name
    return handler


def emit(args: argparse.Namespace, payload: Any, text: str) -> None:
    """Print `payload` as JSON when `--json` was given, else the plain `text`."""
    text = (
        json.dumps(payload, indent=2, default=_json_default)
        if getattr(args, "json", False)
        else printable(terminal_text(text), sys.stdout)
    )
    write_line(text)


def write_line(text: str, stream: Any = None) -> None:
    """Print a line of output and flush it, so that output that cannot be written (a full disk
    behind `> file`, /dev/full) is one ServantError now, not a traceback here or at exit."""
    try:
        print(text, file=stream or sys.stdout, flush=True)
    except BrokenPipeError:
        raise  # the reader has gone: run_handler ends quietly
    except OSError as exc:
        reader_gone()
        raise ServantError(
            f"cannot write the output ({exc.strerror or type(exc).__name__}); "
            "check where it is redirected to"
        ) from None


def one_line(text: str, keep: str = "") -> str:
    """`text` with control characters (a file name may hold a newline) shown as escapes, but
    for those in `keep`."""
    return "".join(c if c.isprintable() or c in keep else repr(c)[1:-1] for c in text)


def terminal_text(text: str) -> str:
    """Lines for the terminal: every control character but newline and tab shown as an escape,
    so that a name from a file (a scene folder, a model header's scene) cannot retitle, clear
    or otherwise command the user's terminal (ESC ] 0 ; title BEL, ESC [ 2 J)."""
    return one_line(text, keep="\n\t")


def printable(text: str, stream: Any) -> str:
    """`text` as `stream` can encode it: a file name that is not UTF-8 keeps its odd bytes
    as `\\udcXX` escapes instead of failing the print."""
    encoding = getattr(stream, "encoding", None) or "utf-8"
    return text.encode(encoding, "backslashreplace").decode(encoding)


def _json_default(value: Any) -> Any:
    import numpy as np

    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def run_handler(args: argparse.Namespace) -> int:
    """Run a parsed subcommand; a ServantError becomes one line on stderr and exit status 2."""
    with library_noise_silenced():
        try:
            return int(args.handler(args) or 0)
        except ServantError as error:
            print(f"servant: error: {one_line(str(error))}", file=sys.stderr)
            return 2
        except KeyboardInterrupt:
            return 130
        except BrokenPipeError:
            return reader_gone()


# The shell's status for a command ended by SIGPIPE: `servant eval ... | head -n 3`.
READER_GONE = 128 + 13


def reader_gone() -> int:
    """The program reading the output has gone (`| head` read enough): nothing more can be
    said, so stdout goes to /dev/null (the exit's flush would raise again) and the command
    ends quietly, as `yes | head` does."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    return READER_GONE


def serve_until_stopped(
    stop_serving: Callable[[], None], message: str, seconds: float | None
) -> int:
    """Print `message`, then wait for Ctrl-C, SIGTERM or `seconds`; `stop_serving()` at the end
    (an emulator's command)."""
    stop = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        print(message, flush=True)
        stop.wait(seconds)
    finally:
        signal.signal(signal.SIGTERM, previous)
        stop_serving()
    return 0


@contextlib.contextmanager
def library_noise_silenced() -> Iterator[None]:
    """Keep what the libraries print out of Servant's own lines on stderr.

    libpng, libjpeg, mpg123 and OpenCV write their warnings straight to file descriptor 2 (not
    through Python), and scikit-learn and numpy raise Python warnings; each problem they see
    is reported by Servant in its own words. Descriptor 2 goes to /dev/null meanwhile, and
    `sys.stderr`, when it writes to descriptor 2, is moved to a copy of the real one.
    Only for headless commands: the TUI draws on that descriptor.
    """
    try:
        sys.stderr.flush()
        real = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no descriptor 2 at all: nothing to keep out
        yield
        return
    python_stderr = sys.stderr
    try:
        moved = python_stderr.fileno() == 2
    except (OSError, ValueError, AttributeError):  # e.g. an in-memory stream under a test
        moved = False
    devnull = os.open(os.devnull, os.O_WRONLY)
    if moved:
        sys.stderr = open(  # noqa: SIM115  # closed in the finally below
            real,
            "w",
            encoding=python_stderr.encoding,
            errors="backslashreplace",
            buffering=1,
            closefd=False,
        )
    os.dup2(devnull, 2)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            yield
    finally:
        if moved:
            sys.stderr.close()
            sys.stderr = python_stderr
        os.dup2(real, 2)
        os.close(real)
        os.close(devnull)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "handler", None) is None:
        parser.print_help()
        return 0
    return run_handler(args)
