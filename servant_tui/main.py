"""The `servant` console script: the TUI, or a headless subcommand of servant_core.cli.

`servant` alone (or `servant run`) opens the TUI on the live devices; `servant demo` opens it on
the demo scenes. With `--headless` (or `demo --fast`) they print lines instead, as servant_core's
other subcommands do. Ctrl-C is quiet at any time, even in the first second, while the engine's
libraries are still being imported: this module imports them only inside `main`, under the same
guard.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import argparse
    from collections.abc import Callable, Sequence

    from servant_tui.app import EngineLike

INTERRUPTED = 130  # the shell's status for a command ended by SIGINT
INTERRUPT_AGAIN_S = 0.05  # Ctrl-C that Python ignored is raised again this much later


def build_parser() -> argparse.ArgumentParser:
    """servant_core's parser: its `demo` and `run` open the TUI here unless `--headless`."""
    from servant_core.cli import build_parser as build_core_parser

    return build_core_parser()


def run_tui(engine_factory: Callable[[], EngineLike], mode: str) -> int:
    from servant_core.errors import ServantError
    from servant_tui.app import ServantApp
    from servant_tui.heap import release_free_heap

    try:
        engine = engine_factory()
    except ServantError as error:
        print(f"servant: error: {error}", file=sys.stderr)
        return 2
    release_free_heap()  # the demo's engine trained its recognisers: most of that is free now
    app = ServantApp(engine, mode=mode)
    app.run()
    return app.return_code or 0


def interrupts_not_ignored(hook: Callable[[Any], None]) -> Callable[[Any], None]:
    """An unraisable-exception hook that passes Ctrl-C on instead of printing it.

    Ctrl-C that lands in code Python may not raise from (a weak reference's callback, such as the
    one importlib runs when it drops a module's lock while a library loads) is printed as
    "Exception ignored in: … KeyboardInterrupt" with a traceback, and the command goes on. Here it
    is raised again in the main thread a moment later, once out of there, where `main` ends
    quietly (130): from a timer's thread, as raised here it would be unraisable again (and if it
    lands in such a place again, it comes round again)."""
    import _thread
    import threading

    def unraisable(info: Any) -> None:
        if isinstance(info.exc_value, KeyboardInterrupt):
            timer = threading.Timer(INTERRUPT_AGAIN_S, _thread.interrupt_main)
            timer.daemon = True
            timer.start()
        else:
            hook(info)

    return unraisable


def main(argv: Sequence[str] | None = None) -> int:
    # Everything under the guard, the first import too: on a busy machine Ctrl-C 0.05 s after
    # start landed in `servant_core.threads`'s imports (logging, threading), outside it, and
    # printed a traceback
    try:
        sys.unraisablehook = interrupts_not_ignored(sys.unraisablehook)
        noting_interrupts()
        from servant_core.threads import one_thread_pools

        one_thread_pools()  # before numpy loads
        return _main(argv)
    except KeyboardInterrupt:  # before a command's own handling of it (importing, parsing)
        return INTERRUPTED
    except ImportError as error:  # Ctrl-C in an extension module's initialisation reads so
        if _interrupted(error):
            return INTERRUPTED
        raise


_interrupts_seen: list[int] = []  # each Ctrl-C, as `noting_interrupts` handles it


def noting_interrupts() -> None:
    """Handle Ctrl-C as Python does (KeyboardInterrupt), noting that it came: one landing while
    an extension module initialises can reach the caller as a plain ImportError, its
    KeyboardInterrupt swallowed in C (numpy at 0.05 s: "PyCapsule_Import could not import module
    'datetime'"), which only the note tells from a broken install. Where Ctrl-C is ignored
    (started in the background), it stays ignored."""
    import signal

    _interrupts_seen.clear()  # a run of its own (tests call `main` again in one process)
    if signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        return  # ignored, or noted already

    def noted(signum: int, frame: Any) -> None:
        _interrupts_seen.append(signum)
        signal.default_int_handler(signum, frame)

    try:
        signal.signal(signal.SIGINT, noted)
    except ValueError:  # not the main thread: Ctrl-C is not delivered here anyway
        pass


def _interrupted(error: BaseException) -> bool:
    """Whether `error` was caused by Ctrl-C (it came while `main` ran, or a KeyboardInterrupt is
    in its chain)."""
    if _interrupts_seen:
        return True
    seen: set[int] = set()
    cause: BaseException | None = error
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False


def _main(argv: Sequence[str] | None) -> int:
    from servant_core.cli import run_handler
    from servant_tui.heap import limit_heaps
    from servant_tui.memtrace import start_from_environment as start_memtrace

    args = build_parser().parse_args(argv)
    limit_heaps()  # before the engine's and Textual's threads start
    start_memtrace()  # a developer option, off unless SERVANT_MEMTRACE is set
    headless = getattr(args, "headless", False)
    # the engine's modules load only for the commands that start one (not for `--help`)
    if args.command is None or (args.command == "run" and not headless and not args.list_devices):
        from servant_core.cli.live import build_run_engine

        return run_tui(lambda: build_run_engine(args if args.command else None), "live")
    if args.command == "demo" and not headless and not args.fast:
        from servant_core.demo.space import throwaway_space
        from servant_core.engine import build_demo_engine
        from servant_core.progress import Progress

        with throwaway_space() as space:
            return run_tui(
                lambda: build_demo_engine(
                    args.seed,
                    paper=args.paper,
                    library_root=space / "library",
                    on_progress=Progress("servant demo: learning the demo's places"),
                    policy=args.policy,
                ),
                "demo",
            )
    return run_handler(args)


if __name__ == "__main__":
    sys.exit(main())
