"""What a place's name may be: the one rule for every name a user gives a place.

A name (stripped) is a library folder, a teach-record label and a word on screen at once, so
`place_name` refuses: over `MAX_NAME_BYTES` bytes of UTF-8; characters of Unicode categories Cc,
Cf, Cs, Co, Zl, Zp; `/` or `\\`, a leading `.`, `.` or `..`; `UNKNOWN`; a non-folder already in the
library. Names are one place when NFKC-normalised and case-folded (`place_key`): a name matching a
known place is that place, in its existing spelling. `printable_name` prints a name found on disk
without letting it split or command a line."""

from __future__ import annotations

import os
import unicodedata
from collections.abc import Iterable
from pathlib import Path

from servant_core.errors import ServantError
from servant_core.senses import UNKNOWN

MAX_NAME_BYTES = 64
# The Unicode categories a name may not hold, in words for the message that refuses one.
REFUSED_CATEGORIES = {
    "Cc": "a control character",
    "Cf": "an invisible formatting character",
    "Cs": "a lone surrogate",
    "Co": "a private-use character",
    "Zl": "a line separator",
    "Zp": "a paragraph separator",
}
SEPARATORS = "/\\"
EXAMPLE = "kitchen"
SHOWN_CHARS = 40  # of a refused name in its message: enough to recognise it, one line still


def place_key(name: str) -> str:
    """The form two names of one place share: NFKC, case-folded, NFKC again (folding can undo
    normalisation, as `ẞ` does)."""
    return unicodedata.normalize("NFKC", unicodedata.normalize("NFKC", name).casefold())


def place_name(
    typed: str, root: str | os.PathLike[str] | None = None, known: Iterable[str] = ()
) -> str:
    """The place a user means by `typed`: an existing place's spelling (a folder of the library
    at `root`, or one of `known`, the places recognisers or teach records know) when it matches
    one, else `typed` itself, stripped and NFC-normalised. ServantError, in one line that says
    what to type instead, when it cannot be a place's name."""
    text = typed.strip()
    folders, others = _library_entries(root)
    if text in folders and text != UNKNOWN:  # a folder already there is a place, whoever named it
        return text
    why = _why_not(text)
    if why is not None:
        raise ServantError(f"{why}; {_instead(text)}")
    key = place_key(text)
    for name in [*folders, *known]:
        if place_key(name) == key:
            return name
    clash = next((name for name in others if place_key(name) == key), None)
    if clash is not None:
        raise ServantError(
            f"place name {_quoted(text)}: {_quoted(clash)} in the library {root} is a file, not "
            f"a place's folder; {_instead(text + ' place')}"
        )
    return unicodedata.normalize("NFC", text)


def _why_not(text: str) -> str | None:
    """What is wrong with `text` as a new place's name, or None."""
    if not text:
        return "a place needs a name"
    refused = next((c for c in text if unicodedata.category(c) in REFUSED_CATEGORIES), None)
    if refused is not None:
        return (
            f"place name {_quoted(text)} holds {REFUSED_CATEGORIES[unicodedata.category(refused)]}"
            f" U+{ord(refused):04X}, which a name cannot show or store"
        )
    size = len(unicodedata.normalize("NFC", text).encode("utf-8"))
    if size > MAX_NAME_BYTES:
        return (
            f"place name {_quoted(text)} is {size} bytes long; a place's name is at most "
            f"{MAX_NAME_BYTES} bytes (as many ASCII letters, fewer of other scripts)"
        )
    if any(c in SEPARATORS for c in text):
        return f"place name {_quoted(text)} holds '/' or '\\', which would make it a path"
    if text in (".", ".."):
        return f"{_quoted(text)} is a folder's own link, not a place's name"
    if text.startswith("."):
        return f"place name {_quoted(text)} starts with '.', which hides its folder"
    if place_key(text) == place_key(UNKNOWN):
        return f"{_quoted(text)} is what Servant calls a place it does not know"
    return None


def _instead(text: str) -> str:
    """What to type instead of `text`: it cleaned of what the rule refuses, if anything is left."""
    kept = "".join(
        "-" if c in SEPARATORS else c
        for c in text
        if unicodedata.category(c) not in REFUSED_CATEGORIES
    )
    cleaned = kept.strip().lstrip(".-").rstrip("-").strip()
    while len(cleaned.encode("utf-8")) > MAX_NAME_BYTES:
        cleaned = cleaned[:-1].rstrip()
    if not cleaned or _why_not(cleaned) is not None:
        cleaned = EXAMPLE
    return f"type a name such as {cleaned!r} instead"


def _quoted(name: str) -> str:
    """`name` for a message: escaped as Python would (never a raw control character), cut."""
    return repr(name if len(name) <= SHOWN_CHARS else name[:SHOWN_CHARS] + "…")


def printable_name(name: str) -> str:
    """A name found on disk as it can be printed on one line: itself when it holds no character
    the rule refuses, else escaped as Python would (`'caf\\ne'`), so a line is never split."""
    if any(unicodedata.category(c) in REFUSED_CATEGORIES for c in name):
        return repr(name)
    return name


def _library_entries(root: str | os.PathLike[str] | None) -> tuple[list[str], list[str]]:
    """(the folders, the other entries) at the top of the library, sorted, hidden ones left
    out as the library leaves them out; none when there is no library there to read (a write
    into it then says why)."""
    if root is None:
        return [], []
    folders: list[str] = []
    others: list[str] = []
    try:
        with os.scandir(Path(root)) as entries:
            for entry in entries:
                if entry.name.startswith("."):
                    continue
                (folders if _is_folder(entry) else others).append(entry.name)
    except OSError:
        return [], []
    return sorted(folders), sorted(others)


def _is_folder(entry: os.DirEntry[str]) -> bool:
    try:
        return entry.is_dir()
    except OSError:
        return False
