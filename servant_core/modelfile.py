"""Model files without pickle: one `.npz` holding the arrays and a JSON header.

The header (format name, version, and per recogniser its sense, method, scenes and parameters)
is stored as a 0-d unicode array named `header`; a recogniser's arrays are stored as
`<role>/<name>`. Loading uses `allow_pickle=False`, so a file can never run code.
"""

from __future__ import annotations

import json
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from servant_core.errors import ServantError
from servant_core.recognisers import Recogniser, methods_for
from servant_core.storage import atomic_save_npz

FORMAT = "servant-model"
VERSION = 1


def save_model(path: str | Path, recognisers: dict[str, Recogniser]) -> Path:
    """Save recognisers by role (e.g. "acoustic", "visual") into one model file, atomically."""
    header: dict[str, Any] = {"format": FORMAT, "version": VERSION, "recognisers": {}}
    arrays: dict[str, np.ndarray] = {}
    for role, recogniser in recognisers.items():
        state, parts = recogniser.get_state()
        header["recognisers"][role] = {
            "sense": recogniser.sense,
            "method": recogniser.method,
            **state,
        }
        for name, array in parts.items():
            arrays[f"{role}/{name}"] = np.asarray(array)
    arrays["header"] = np.array(json.dumps(header))
    return atomic_save_npz(path, arrays)


def load_model(path: str | Path) -> dict[str, Recogniser]:
    """Load a model file written by `save_model`; anything else is refused in one clear line."""
    path = Path(path)
    if not path.is_file():
        raise ServantError(
            f"{path}: no such model file; train one with `servant train ROOT -o {path}`"
        )
    try:
        with np.load(path, allow_pickle=False) as npz:
            files = {name: npz[name] for name in npz.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ServantError(f"{path}: not a Servant model file (corrupt or another format)") from exc
    try:
        header = json.loads(str(files.pop("header")))
        fmt, version = header["format"], int(header["version"])
    except (KeyError, ValueError, TypeError) as exc:
        raise ServantError(f"{path}: not a Servant model file (no valid header)") from exc
    if fmt != FORMAT:
        raise ServantError(f"{path}: not a Servant model file (format {fmt!r})")
    if version > VERSION:
        raise ServantError(
            f"{path}: model format version {version} is newer than this Servant reads ({VERSION}); "
            "upgrade Servant or retrain the model"
        )
    if version < 1:
        raise ServantError(f"{path}: unknown model format version {version}; retrain the model")
    recognisers: dict[str, Recogniser] = {}
    try:
        for role, state in header["recognisers"].items():
            methods = methods_for(state["sense"])
            if state["method"] not in methods:
                raise ServantError(
                    f"{path}: {state['sense']} method {state['method']!r} is not known to this "
                    "Servant; upgrade Servant or retrain the model"
                )
            prefix = f"{role}/"
            parts = {k[len(prefix) :]: v for k, v in files.items() if k.startswith(prefix)}
            recognisers[role] = methods[state["method"]].from_state(state, parts)
    except (KeyError, ValueError, TypeError) as exc:
        raise ServantError(
            f"{path}: damaged Servant model file ({exc!r}); retrain the model"
        ) from exc
    return recognisers
