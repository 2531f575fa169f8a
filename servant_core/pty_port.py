"""A pseudo-terminal pair standing in for a USB serial device: what the emulators serve on.

The emulator keeps `master`; the host opens `port` (the slave's name, or a symlink to it) with
pyserial exactly as it would open a real device. Closing the pair is, to the host, the cable
pulled.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import threading
import tty
from collections.abc import Callable
from pathlib import Path
from typing import Self

from servant_core.errors import ServantError

PTY_FOLDER = "/dev/pts/"  # where Linux's pseudo-terminals are (what a stale link points to)


class PtyPort:
    def __init__(self, link: str | Path | None = None) -> None:
        """Open a pty pair; with `link`, also make that path a symlink to its port."""
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)  # no echo, no line editing: a serial line carries bytes as they are
        self.device = os.ttyname(self.slave)
        self.link: Path | None = None
        if link is not None:
            try:
                self.link = _make_link(Path(link), self.device)
            except BaseException:
                self.close()
                raise

    @property
    def port(self) -> str:
        """What the host opens: the link if one was made, else the device."""
        return str(self.link) if self.link else self.device

    def close(self) -> None:
        """Close both sides and remove the link (if it still points here); safe to call twice."""
        for fd in (self.master, self.slave):
            if fd >= 0:
                os.close(fd)
        self.master = self.slave = -1
        if (
            self.link is not None
            and self.link.is_symlink()
            and os.readlink(self.link) == self.device
        ):
            self.link.unlink()
        self.link = None


def _make_link(path: Path, device: str) -> Path:
    """Make `path` a symlink to `device`, atomically. Only a stale link of an earlier run (to a
    pseudo-terminal, or to nothing) may be replaced: any other file or link there is the
    user's, and is left alone."""
    if path.is_symlink():
        stale = not path.exists() or os.readlink(path).startswith(PTY_FOLDER)
        if not stale:
            raise ServantError(
                f"{path}: is a link to {os.readlink(path)}, not to a pseudo-terminal, so it is "
                "not replaced; give a new name for the link, or remove it first"
            )
    elif path.exists():
        raise ServantError(
            f"{path}: exists and is not a link, so it is not replaced; "
            "give a new name for the link, or remove the file first"
        )
    # a fresh, unguessable name beside the link: an existing file is never touched
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(8)}.tmp")
    try:
        tmp.symlink_to(device)
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            if tmp.is_symlink():
                tmp.unlink()
        raise ServantError(
            f"{path}: cannot make it a link to the emulator's port ({exc.strerror}); "
            "give a path in a folder you can write to"
        ) from exc
    return path


def _announced_folder() -> Path:
    from servant_core.storage import runtime_dir

    return runtime_dir() / "ports"


def announce(port: str, description: str) -> Callable[[], None]:
    """Leave word that `port` is served by this process, described as `description`, so that
    `servant servo list-ports` lists it beside the machine's own ports (which a pseudo-terminal
    is not among). Returns what withdraws the word; a word left by a process that died is
    ignored (and removed) by `announced_ports`. Best effort: a folder that cannot be written
    only leaves the port unlisted."""
    folder = _announced_folder()
    entry = folder / f"{os.getpid()}-{secrets.token_hex(4)}.json"
    with contextlib.suppress(OSError):
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        record = {"port": port, "pid": os.getpid(), "description": description}
        from servant_core.storage import atomic_write_json

        atomic_write_json(entry, record)
    return lambda: entry.unlink(missing_ok=True)


def announced_ports() -> list[dict[str, str]]:
    """The ports running emulators announced (`announce`) whose process lives and whose port
    is still there, as `{"port", "description"}`."""
    found: list[dict[str, str]] = []
    try:
        entries = sorted(_announced_folder().glob("*.json"))
    except OSError:
        return found
    for entry in entries:
        try:
            record = json.loads(entry.read_text(encoding="utf-8"))
            port, pid, said = str(record["port"]), int(record["pid"]), str(record["description"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if _alive(pid) and os.path.exists(port):
            found.append({"port": port, "description": said})
        else:
            with contextlib.suppress(OSError):
                entry.unlink()
    return found


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return pid > 0
    return pid > 0


class PtyService:
    """What the emulators share: a thread serving a `PtyPort` until `stop()`, which closes it
    (to the host, the device unplugged); a context manager that stops on leaving."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._pty: PtyPort | None = None

    def stop(self) -> None:
        """Stop serving and close the pty: to the host this is the device unplugged."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self._pty is not None:
            self._pty.close()
            self._pty = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
