"""Where the program keeps its files, and how it writes them without ever leaving half a file."""

from __future__ import annotations

import contextlib
import io
import json
import os
import stat
import tempfile
import time
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, BinaryIO

import platformdirs

from servant_core.errors import ServantError

try:
    import fcntl
except ImportError:  # Windows: no locks on files this way; temporaries go by their age
    fcntl = None  # type: ignore[assignment]

if TYPE_CHECKING:  # numpy loads with the one function that needs it: settings stay light
    import numpy as np

APP_NAME = "servant"


def data_dir() -> Path:
    """The user's data directory (recordings, pictures, teach records, models).

    `SERVANT_DATA_DIR` overrides it, which is how tests and scripts keep away from the real one.
    """
    override = os.environ.get("SERVANT_DATA_DIR")
    return Path(override) if override else Path(platformdirs.user_data_dir(APP_NAME))


def default_model_file() -> Path:
    """The model `servant` alone starts with, and where teach mode's retrains are saved."""
    return data_dir() / "model.npz"


def config_dir() -> Path:
    """The user's configuration directory (settings); `SERVANT_CONFIG_DIR` overrides it."""
    override = os.environ.get("SERVANT_CONFIG_DIR")
    return Path(override) if override else Path(platformdirs.user_config_dir(APP_NAME))


def runtime_dir() -> Path:
    """Where running programs leave word of themselves for this user (an emulator's port):
    `SERVANT_RUNTIME_DIR`, else the platform's runtime folder where it exists (it is made at
    login, not by programs), else a folder of this user's in the temporary directory."""
    override = os.environ.get("SERVANT_RUNTIME_DIR")
    if override:
        return Path(override)
    runtime = Path(platformdirs.user_runtime_dir(APP_NAME))
    if runtime.parent.is_dir():
        return runtime
    return Path(tempfile.gettempdir()) / f"{APP_NAME}-{os.getuid()}"


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write `data` to a temporary file beside `path`, then `os.replace` it into place.

    A file replaced keeps its permissions (a 0644 model stays 0644, not the temporary's 0600).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    try:
        old_mode: int | None = stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        old_mode = None
    fd, tmp = _locked_temporary(path)
    try:
        if old_mode is not None:
            os.fchmod(fd, old_mode)
        with os.fdopen(fd, "wb") as handle:  # closed, and so unlocked, only once renamed
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
            os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _sync_directory(path.parent)
    return path


def _locked_temporary(path: Path) -> tuple[int, str]:
    """A new temporary beside `path` (`.NAME.XXXXXXXX.tmp`, open for writing), locked while
    this process writes it. The kernel drops the lock when the process ends, however it ends:
    a temporary nobody holds is one a killed writer left (`remove_stale_temporaries`)."""
    while True:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        _lock(fd, wait=True)
        if _names(tmp, fd):
            return fd, tmp
        os.close(fd)  # taken for a killed writer's between its making and its lock, and removed


def _lock(fd: int, wait: bool) -> bool | None:
    """Lock the file open at `fd` for this process (`flock`, exclusive): True when locked,
    False when another holds it (without `wait`), None where files cannot be locked."""
    if fcntl is None:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
    except BlockingIOError:
        return False
    except OSError:  # e.g. a file system without locks
        return None
    return True


def _names(name: str, fd: int) -> bool:
    """Whether `name` is still the file open at `fd`."""
    try:
        named, opened = os.stat(name, follow_symlinks=False), os.fstat(fd)
    except OSError:
        return False
    return (named.st_dev, named.st_ino) == (opened.st_dev, opened.st_ino)


def file_stamp(path: str | os.PathLike[str]) -> tuple[int, int, int] | None:
    """What changes when a file is replaced or rewritten (inode, size, modification time in ns);
    None when there is no such file. Two stamps that differ: someone wrote it in between."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_ino, st.st_size, st.st_mtime_ns)


def numbered_backup(path: str | os.PathLike[str]) -> Path | None:
    """Keep the file at `path` as `STEM.N.SUFFIX` beside it (N the first number free), before it
    is replaced; None when there is no file. A hard link where the file system has them (instant,
    and `path` is never missing), else an atomic copy."""
    path = Path(path)
    if not path.is_file():
        return None
    for n in range(1, 10_000):
        backup = path.with_name(f"{path.stem}.{n}{path.suffix}")
        if backup.exists() or backup.is_symlink():
            continue
        try:
            os.link(path, backup)
        except FileExistsError:
            continue
        except OSError:
            atomic_write_bytes(backup, path.read_bytes())
        _sync_directory(path.parent)
        return backup
    raise ServantError(f"{path}: 9,999 backups of it already; move some away")


# A write takes seconds at most: a temporary this old was left by a process killed mid-write,
# the one sign of it where files cannot be locked (see `_removed_if_abandoned`).
STALE_TEMPORARY_SECONDS = 3600.0


def remove_stale_temporaries(path: Path, now: float | None = None) -> list[Path]:
    """Remove the temporaries of earlier writes of `path` (`.NAME.XXXXXXXX.tmp`, as
    `atomic_write_bytes` names them) that a killed process left: those no writer holds locked
    (a `servant train` or retrain killed mid-save left one until a save an hour later), and
    any an hour old or more. A temporary of a write going on now is locked and kept. Returns
    those removed."""
    now = time.time() if now is None else now
    prefix = f".{path.name}."
    removed: list[Path] = []
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return removed
    for entry in entries:
        name = entry.name
        if not (name.startswith(prefix) and name.endswith(".tmp")):
            continue
        if len(name) != len(prefix) + 8 + len(".tmp"):  # mkstemp's 8 characters, no other file
            continue
        with contextlib.suppress(OSError):
            if _removed_if_abandoned(entry.path):
                removed.append(Path(entry.path))
            elif now - entry.stat(follow_symlinks=False).st_mtime >= STALE_TEMPORARY_SECONDS:
                os.unlink(entry.path)
                removed.append(Path(entry.path))
    return removed


def _removed_if_abandoned(name: str) -> bool:
    """Remove the temporary `name` if no process holds it locked (its writer was killed);
    whether it was removed. Removed while locked here, so that no writer takes it meanwhile."""
    try:
        fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOFOLLOW", 0))
    except OSError:
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode) or not _lock(fd, wait=False):
            return False
        if not _names(name, fd):
            return False
        os.unlink(name)
        return True
    finally:
        os.close(fd)


def _sync_directory(folder: Path) -> None:
    """Make a rename in `folder` survive a power cut (where the platform can open folders)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return  # e.g. Windows: a folder cannot be opened this way; the rename itself stands
    try:
        with contextlib.suppress(OSError):  # some file systems refuse fsync on a folder
            os.fsync(fd)
    finally:
        os.close(fd)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | os.PathLike[str], obj: Any) -> Path:
    return atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True) + "\n")


def atomic_save_npz(path: str | os.PathLike[str], arrays: dict[str, np.ndarray]) -> Path:
    """Save arrays as an uncompressed `.npz`, atomically. Object arrays are refused (no pickle)."""
    import numpy as np

    for name, array in arrays.items():
        if np.asarray(array).dtype == object:
            raise TypeError(f"array {name!r} has dtype object, which would need pickle")
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)  # type: ignore[arg-type]  # numpy's stub types **kwds oddly
    return atomic_write_bytes(path, buffer.getvalue())


# Linux and macOS allow 255 bytes a name; the temporary file `.NAME.XXXXXXXX.tmp` adds 14.
MAX_NAME_BYTES = 255 - 14


def check_replaceable(
    path: str | os.PathLike[str], what: str, is_kind: Callable[[Path], bool]
) -> None:
    """Refuse to write `what` at `path` when that would destroy something else: a symbolic link
    (replacing it loses the link, following it writes where the user did not say), an
    existing file that `is_kind` does not recognise as a `what` (a recording, a document), a
    name a scene library would read as a recording, picture or sensor log, or a folder that
    cannot be written. Called before the work whose result is written, so nothing is lost."""
    from servant_core.senses import sense_of_file  # senses needs audio, which needs storage

    path = Path(path)
    if len(os.fsencode(path.name)) > MAX_NAME_BYTES:
        raise ServantError(
            f"{str(path)[:60]}...: a file name of {len(os.fsencode(path.name))} bytes is longer "
            f"than {MAX_NAME_BYTES}; choose a shorter name"
        )
    sense = sense_of_file(path.name)
    if sense is not None:
        raise ServantError(
            f"{path}: a scene library reads a file of this name as {sense.name} data; "
            f"give the {what} a name ending in .npz"
        )
    try:
        if path.is_symlink():
            raise ServantError(
                f"{path}: is a symbolic link; give the file's own path "
                f"({os.path.realpath(path)}) or another name"
            )
        exists = path.exists() and not path.is_dir()
    except OSError as exc:  # e.g. a folder on the way that cannot be searched
        raise ServantError(f"{path}: cannot write the {what} there ({os_reason(exc)})") from None
    if exists and not is_kind(path):
        raise ServantError(
            f"{path}: exists and is not {_article(what)}, so it is not overwritten; "
            "move it away or choose another name"
        )
    if exists and _read_only(path):
        raise ServantError(
            f"{path}: is read-only, so it is not overwritten; make it writable "
            "(chmod u+w) or choose another name"
        )
    _check_folder_writable(path, what)


def _check_folder_writable(path: Path, what: str) -> None:
    """Refuse a `what` at `path` whose folder cannot be written: a file on the way where a folder
    should be, or a folder this user may not write. Folders still missing are fine when the
    nearest one that exists can be written: the write makes them."""
    folder = path.absolute().parent
    while not os.path.exists(folder) and folder != folder.parent:  # os.path: never raises
        folder = folder.parent
    if not os.path.isdir(folder):
        raise ServantError(
            f"{path}: cannot save the {what} there: {folder} is a file, not a folder; "
            "choose another place"
        )
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ServantError(
            f"{path}: cannot save the {what} there: the folder {folder} is not writable; "
            "choose another place, or make the folder writable"
        )


def _read_only(path: Path) -> bool:
    """A file this user may not write, or whose owner made it read-only (`chmod a-w`): a
    replacement by rename never asks the file itself, so its mode is asked here (as root too)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not mode & stat.S_IWUSR or not os.access(path, os.W_OK)


# A model's header is at most a million characters (4 bytes each in the array); more is no header.
MAX_HEADER_MEMBER_BYTES = 8 << 20


def servant_npz_format(path: Path) -> str | None:
    """The `format` a `.npz` that Servant wrote names in its JSON header (`servant-model`,
    `servant-action-learner`); None for any other file, or one whose header cannot be read."""
    import numpy as np

    from servant_core.numbers import json_loads  # numbers is light; imported where needed

    try:
        with open_regular_file(path, "file") as handle, zipfile.ZipFile(handle) as archive:
            info = archive.getinfo("header.npy")
            if info.file_size > MAX_HEADER_MEMBER_BYTES:
                return None
            with archive.open(info) as member:
                header = np.load(io.BytesIO(member.read()), allow_pickle=False)
        found = json_loads(str(header)).get("format")
    except (ServantError, OSError, zipfile.BadZipFile, KeyError, ValueError, EOFError):
        return None
    except (AttributeError, TypeError, RecursionError):  # a header that is not a JSON object
        return None
    return found if isinstance(found, str) else None


def is_servant_npz_of(fmt: str) -> Callable[[Path], bool]:
    """A test for `check_replaceable`: the file is a Servant `.npz` of format `fmt` (a model
    file is never taken for an action learner's, nor the other way round)."""
    return lambda path: servant_npz_format(path) == fmt


def no_file_yet(path: Path, what: str, fix: str) -> bool:
    """Whether there is no file at `path` yet (the caller uses its defaults). A link there that
    leads to no file, its target gone or the links in a loop, is said, not taken for "none
    yet": the user's settings or records would silently be the defaults."""
    if path.exists():
        return False
    if path.is_symlink():
        raise ServantError(
            f"{path}: the {what} is a link that leads to no file (its target is missing, or "
            f"the links loop); {fix}"
        )
    return True


def open_regular_file(path: str | os.PathLike[str], what: str) -> BinaryIO:
    """Open a file for reading in Python (any file name works, even one that is not UTF-8);
    a missing file, a folder, a FIFO or a device is refused without blocking on it.

    The file is opened without blocking and checked on the open descriptor, so a FIFO put in
    its place between a check and the open cannot hang the program either.
    """
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
    except FileNotFoundError:
        raise ServantError(f"{path}: no such file; check the path") from None
    except OSError as exc:
        raise ServantError(f"{path}: cannot open the {what} ({os_reason(exc)})") from None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise ServantError(f"{path}: not a regular file; give {_article(what)}")
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_bounded_bytes(path: str | os.PathLike[str], what: str, max_bytes: int) -> bytes:
    """The whole of a regular file of at most `max_bytes`; anything else one ServantError.
    The size is checked before reading, and the read stops one byte past the bound (a file
    growing meanwhile, or a /proc file that claims 0 bytes)."""
    path = Path(path)
    with open_regular_file(path, what) as handle:
        try:
            if os.fstat(handle.fileno()).st_size > max_bytes:
                raise _too_big(path, what, max_bytes)
            data = handle.read(max_bytes + 1)
        except OSError as exc:
            raise ServantError(f"{path}: cannot read the {what} ({os_reason(exc)})") from None
    if len(data) > max_bytes:
        raise _too_big(path, what, max_bytes)
    return data


def _too_big(path: Path, what: str, max_bytes: int) -> ServantError:
    return ServantError(
        f"{path}: larger than any {what} ({max_bytes / 2**20:g} MiB at most); "
        "check that it is the right file"
    )


def _article(what: str) -> str:
    return f"an {what}" if what[:1] in "aeiou" else f"a {what}"


def os_reason(exc: OSError) -> str:
    """The operating system's short reason ("Permission denied"), not the whole repr."""
    return exc.strerror or type(exc).__name__


# A scene library keeps its files a few folders below each scene; hundreds of levels are a
# mistake or an attack (1,100 levels once exhausted Python's recursion in `Path.rglob`).
MAX_FOLDER_DEPTH = 64


def walk_files(folder: str | os.PathLike[str], max_depth: int = MAX_FOLDER_DEPTH) -> list[Path]:
    """Every file below `folder` (following links to folders, each folder visited once: a link
    back up is no loop), sorted; without recursion, so depth costs no stack. A folder deeper
    than `max_depth` is one ServantError; an OSError reading a folder propagates."""
    root = Path(folder)
    files: list[Path] = []
    seen: set[tuple[int, int]] = set()
    pending: list[tuple[Path, int]] = [(root, 0)]
    while pending:
        current, depth = pending.pop()
        info = os.stat(current)
        if (info.st_dev, info.st_ino) in seen:
            continue
        seen.add((info.st_dev, info.st_ino))
        with os.scandir(current) as entries:
            for entry in entries:
                path = current / entry.name
                try:
                    is_dir = entry.is_dir()
                except OSError:
                    continue  # e.g. a link to a folder that cannot be read: not a file either
                if not is_dir:
                    files.append(path)
                elif depth + 1 > max_depth:
                    raise ServantError(
                        f"{root}: folders nested more than {max_depth} levels deep "
                        f"({str(path)[:80]}...); move the files nearer the top"
                    )
                else:
                    pending.append((path, depth + 1))
    return sorted(files)
