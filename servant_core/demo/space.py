"""The demo's throw-away space: it never writes into the user's library, models or settings."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

# the variables `servant_core.storage.data_dir()` and `config_dir()` obey
DIRECTORY_VARIABLES = ("SERVANT_DATA_DIR", "SERVANT_CONFIG_DIR")


@contextlib.contextmanager
def throwaway_space() -> Iterator[Path]:
    """Point the data and config dirs of this process at a new temporary folder while the
    context lasts, then delete it: what the demo records, teaches, trains and saves goes there."""
    saved = {name: os.environ.get(name) for name in DIRECTORY_VARIABLES}
    with tempfile.TemporaryDirectory(prefix="servant-demo-") as folder:
        root = Path(folder)
        os.environ["SERVANT_DATA_DIR"] = str(root / "data")
        os.environ["SERVANT_CONFIG_DIR"] = str(root / "config")
        try:
            yield root
        finally:
            for name, value in saved.items():
                if value is None:
                    os.environ.pop(name, None)
                else:
                    os.environ[name] = value
