"""Model files without pickle: one `.npz` holding the arrays and a JSON header.

The header (format name, version, and per recogniser its sense, method, scenes and parameters)
is stored as a 0-d unicode array named `header`; a recogniser's arrays are stored as
`<role>/<name>`. The learned fusion's net, when there is one, is the header's `fusion` entry and
the arrays `fusion/<name>` (a reader that does not know it ignores it). Loading uses
`allow_pickle=False`, so a file can never run code.
"""

from __future__ import annotations

import collections.abc
import json
import math
import typing
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from servant_core.audio import (
    MAX_RATE,
    MAX_WINDOW_SECONDS,
    MIN_RATE,
    MIN_WINDOW_SECONDS,
    first_line,
)
from servant_core.errors import ServantError
from servant_core.fusion.net import FusionNet
from servant_core.numbers import is_finite_number, json_loads
from servant_core.recognisers import UNKNOWN, Recogniser, methods_for
from servant_core.senses import ROLE_SENSE
from servant_core.storage import (
    atomic_save_npz,
    check_replaceable,
    file_stamp,
    is_servant_npz_of,
    numbered_backup,
    open_regular_file,
    os_reason,
)

FORMAT = "servant-model"
VERSION = 1
FUSION = "fusion"

# What a model file may hold, checked before anything is read in full. The largest real model
# (the paper's FFT centroids, ten scenes) is about 10 MB; these limits leave ample room and keep
# a 5 MB file that claims a 4 GB member (a zip bomb) from being inflated.
MAX_MEMBERS = 256
MAX_MEMBER_BYTES = 256 * 1024 * 1024
MAX_TOTAL_BYTES = 512 * 1024 * 1024
MAX_HEADER_CHARS = 1_000_000
# Parameters that size the work of featurizing (a picture resized to `size`², `n_mels` bands...):
# bounded so that a doctored header cannot ask for gigabytes. Other numbers get GENERIC_LIMIT.
PARAM_LIMITS: dict[str, tuple[float, float]] = {
    "rate": (MIN_RATE, MAX_RATE),
    "window_seconds": (MIN_WINDOW_SECONDS, MAX_WINDOW_SECONDS),
    "frame_seconds": (0.001, 1.0),
    "fmin": (0.0, MAX_RATE / 2),
    "fmax": (0.0, MAX_RATE / 2),
    "n_mels": (1, 512),
    "crop_fraction": (0.0, 1.0),  # kmeans-encoder: a part of a window
    # kmeans-encoder divides its logits by it: near 0 every probability is 0 or 1 (and overflows),
    # far above 10 every scene gets the same share
    "temperature": (0.1, 10.0),
    # kmeans-encoder scales the encodings' columns by it in the head (0: statistics only)
    "encoding_weight": (0.0, 10.0),
    "n_colours": (1, 64),
    "size": (8, 2048),
    "second_size": (8, 2048),
    "cell": (1, 256),
    "n_bins": (1, 360),
    # fisher-bovw: dense SIFT's cell widths and grid step, its PCA and mixture, the head's space
    "bin_sizes": (1, 64),
    "step": (1, 256),
    "pca_dim": (1, 128),
    "n_components": (1, 512),
    "head_dim": (1, 4096),
    "max_mixture_descriptors": (1, 10_000_000),
}
GENERIC_LIMIT = (-1e9, 1e9)
# the senses whose `rate` is a sensor's readings a second, not an audio sample rate
SENSOR_RATE_LIMITS = {"motion": (1, 2000), "ambient": (1, 100)}


def save_model(
    path: str | Path, recognisers: dict[str, Recogniser], fusion: FusionNet | None = None
) -> Path:
    """Save recognisers by role (e.g. "acoustic", "visual"), and the learned fusion's net if
    given, into one model file, atomically."""
    header: dict[str, Any] = {"format": FORMAT, "version": VERSION, "recognisers": {}}
    arrays: dict[str, np.ndarray] = {}
    if fusion is not None:
        header[FUSION], parts = fusion.get_state()
        arrays |= {f"{FUSION}/{name}": np.asarray(a) for name, a in parts.items()}
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
    path = check_model_output(path)
    try:
        return atomic_save_npz(path, arrays)
    except OSError as exc:
        raise ServantError(
            f"{path}: cannot save the model ({os_reason(exc)}); the previous file is unchanged, "
            "choose another place"
        ) from None


def replace_model(
    path: Path,
    recognisers: dict[str, Recogniser],
    fusion: FusionNet | None,
    stamp: tuple[int, int, int] | None,
    backup: bool = True,
) -> Path | None:
    """`save_model` for a run that began when `path` had `stamp` (`file_stamp`): refused when
    another writer (a second `servant train`, the app's retrain) changed it since, so that the
    last one does not silently win; with `backup`, the model replaced is kept as a numbered
    backup, returned."""
    if file_stamp(path) != stamp:
        raise ServantError(
            f"{path}: was written by someone else while this training ran (another `servant "
            "train`, or the app's retrain); it is left as they wrote it: train again, or give "
            "-o FILE"
        )
    try:
        kept = numbered_backup(path) if backup else None
    except OSError as exc:
        raise ServantError(
            f"{path}: cannot keep a backup of the model there ({os_reason(exc)}); the previous "
            "file is unchanged, give -o FILE"
        ) from None
    save_model(path, recognisers, fusion)
    return kept


def check_model_output(path: str | Path) -> Path:
    """`path` if a model may be saved there: not a folder, nor a file that is not a model."""
    path = Path(path)
    check_replaceable(path, "model file", is_servant_npz_of(FORMAT))
    if path.is_dir():
        raise ServantError(f"{path}: is a folder; give a model file name such as {path}/model.npz")
    return path


def load_model(path: str | Path) -> dict[str, Recogniser]:
    """Load a model file written by `save_model`; anything else is refused in one clear line.

    Every size, header field and array is checked against its method before use, and each
    recogniser must then recognise a made-up window or picture with finite numbers.
    """
    return load_model_and_fusion(path)[0]


def load_model_and_fusion(path: str | Path) -> tuple[dict[str, Recogniser], FusionNet | None]:
    """`load_model`, and the learned fusion's net saved with the recognisers (None: none was),
    checked as strictly: its parameters, names and layer shapes, then one finite decision."""
    path = Path(path)
    if not path.exists():
        raise ServantError(
            f"{path}: no such model file; train one with `servant train ROOT -o {path}`"
        )
    files = _read_arrays(path)
    header = _read_header(path, files.pop("header", None))
    recognisers: dict[str, Recogniser] = {}
    for role, state in header["recognisers"].items():
        recognisers[role] = _recogniser(path, role, state, _parts(files, role))
    fusion = header.get(FUSION)
    if fusion is None:
        return recognisers, None
    net = _fusion_net(path, fusion, _parts(files, FUSION))
    _check_net_fits(path, net, recognisers)
    return recognisers, net


def _check_net_fits(path: Path, net: FusionNet, recognisers: dict[str, Recogniser]) -> None:
    """The net fuses the model's own recognisers: each of its senses is one of them, and each
    scene it can decide is one they know (a net naming `office` in a cafe model would announce
    a place no sense of the model can recognise)."""
    senses = {r.sense for r in recognisers.values()}
    scenes = {scene for r in recognisers.values() for scene in r.scenes_}
    foreign = [s for s in net.senses_ if s not in senses]
    if foreign:
        raise _damaged(
            path, f"{FUSION}: it fuses {str(foreign[0])[:40]!r}, a sense the model lacks"
        )
    unknown = [s for s in net.scenes_ if s not in scenes]
    if unknown:
        raise _damaged(
            path, f"{FUSION}: it decides {str(unknown[0])[:40]!r}, a scene no recogniser knows"
        )


def _parts(files: dict[str, np.ndarray], role: str) -> dict[str, np.ndarray]:
    prefix = f"{role}/"
    return {k[len(prefix) :]: v for k, v in files.items() if k.startswith(prefix)}


def _fusion_net(path: Path, state: Any, parts: dict[str, np.ndarray]) -> FusionNet:
    try:
        if not isinstance(state, dict) or not isinstance(state.get("params"), dict):
            raise ValueError("no parameters")
        _check_params(FusionNet, state["params"], FUSION)
        _check_arrays(parts)
        net = FusionNet.from_state(state, parts)
        proba = net.predict_proba(net.features({}))
        if proba.shape != (1, len(net.scenes_)) or not np.all(np.isfinite(proba)):
            raise ValueError("its arrays do not fit its scenes")
    except (ValueError, KeyError, TypeError) as exc:
        raise _damaged(path, f"{FUSION}: {first_line(exc)[:120]}") from None
    return net


def _damaged(path: Path, what: str) -> ServantError:
    return ServantError(f"{path}: damaged Servant model file ({what}); retrain the model")


def _read_arrays(path: Path) -> dict[str, np.ndarray]:
    """The arrays of the npz, each member's declared size checked before it is read."""
    not_model = ServantError(f"{path}: not a Servant model file (corrupt or another format)")
    with open_regular_file(path, "model file") as handle:
        try:
            with zipfile.ZipFile(handle) as archive:
                infos = archive.infolist()
                if len(infos) > MAX_MEMBERS or sum(i.file_size for i in infos) > MAX_TOTAL_BYTES:
                    raise _damaged(path, "more data than any model holds")
                return {_member_name(path, i): _read_member(path, archive, i) for i in infos}
        except OSError as exc:
            raise ServantError(f"{path}: cannot read the model file ({os_reason(exc)})") from None
        except (zipfile.BadZipFile, zipfile.LargeZipFile, ValueError, EOFError, KeyError):
            raise not_model from None
        except NotImplementedError:  # a compression method zipfile does not have
            raise not_model from None


def _member_name(path: Path, info: zipfile.ZipInfo) -> str:
    if not info.filename.endswith(".npy"):
        raise ServantError(f"{path}: not a Servant model file (holds {info.filename!r})")
    return info.filename[: -len(".npy")]


def _read_member(path: Path, archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    if info.file_size > MAX_MEMBER_BYTES:
        raise _damaged(path, f"{info.filename} claims {info.file_size} bytes")
    fmt = np.lib.format
    with archive.open(info) as member:
        try:
            version = fmt.read_magic(member)
            if version == (1, 0):
                shape, _, dtype = fmt.read_array_header_1_0(member)
            elif version == (2, 0):
                shape, _, dtype = fmt.read_array_header_2_0(member)
            else:
                raise ValueError(f"array format {version}")
        except (zipfile.BadZipFile, EOFError):
            raise
        except Exception:  # numpy parses the header as Python: TokenError, SyntaxError...
            raise _damaged(path, f"{info.filename} has a bad array header") from None
        # The array must fit in what the member declares (zipfile never inflates beyond that):
        # numpy would otherwise allocate whatever the array header claims first.
        if dtype.hasobject:
            raise ServantError(
                f"{path}: not a Servant model file (it holds pickled objects, never loaded)"
            )
        if math.prod(shape) * dtype.itemsize > info.file_size:
            raise _damaged(path, f"{info.filename} has a bad array header")
    with archive.open(info) as member:
        return np.asarray(fmt.read_array(member, allow_pickle=False))


def _no_nan(constant: str) -> float:
    if constant == "NaN":
        raise ValueError("NaN in the header")
    return float(constant)  # Infinity: a rejection distance not measured yet


def _read_header(path: Path, stored: np.ndarray | None) -> dict[str, Any]:
    no_header = ServantError(f"{path}: not a Servant model file (no valid header)")
    if stored is None or stored.shape != () or stored.dtype.kind != "U":
        raise no_header
    text = str(stored)
    if len(text) > MAX_HEADER_CHARS:
        raise _damaged(path, "a header longer than any model has")
    try:
        header = json_loads(text, parse_constant=_no_nan)
    except (ValueError, RecursionError):
        raise no_header from None
    if not isinstance(header, dict) or "format" not in header or "version" not in header:
        raise no_header
    fmt, version = header["format"], header["version"]
    if fmt != FORMAT:
        raise ServantError(f"{path}: not a Servant model file (format {str(fmt)[:40]!r})")
    if type(version) is not int:
        raise ServantError(f"{path}: model format version {str(version)[:20]!r} is not a number")
    if version > VERSION:
        raise ServantError(
            f"{path}: model format version {version} is newer than this Servant reads ({VERSION}); "
            "upgrade Servant or retrain the model"
        )
    if version < 1:
        raise ServantError(f"{path}: unknown model format version {version}; retrain the model")
    roles = header.get("recognisers")
    if not isinstance(roles, dict) or not roles:
        raise _damaged(path, "no recogniser")
    for role, state in roles.items():
        if role not in ROLE_SENSE or not isinstance(state, dict):
            raise _damaged(path, f"unknown recogniser {str(role)[:40]!r}")
        if state.get("sense") != ROLE_SENSE[role]:
            raise _damaged(
                path, f"the {role} recogniser has sense {str(state.get('sense'))[:40]!r}"
            )
    return header


def _recogniser(
    path: Path, role: str, state: dict[str, Any], parts: dict[str, np.ndarray]
) -> Recogniser:
    methods = methods_for(state["sense"])
    method = state.get("method")
    if not isinstance(method, str) or method not in methods:
        raise ServantError(
            f"{path}: {state['sense']} method {str(method)[:40]!r} is not known to this "
            "Servant; upgrade Servant or retrain the model"
        )
    cls = methods[method]
    try:
        _check_params(cls, state.get("params"), state["sense"])
        _check_scenes(state)
        _check_arrays(parts)
        # methods with a discriminative head keep their only centroids under `novelty`
        if "centres" in parts or not isinstance(state.get("novelty"), dict):
            _check_centroids(state, parts, "", state["scenes"])
        if isinstance(state.get("novelty"), dict):
            _check_centroids(state["novelty"], parts, "novelty_", state["scenes"])
    except ValueError as exc:
        raise _damaged(path, f"{role}: {exc}") from None
    try:
        recogniser = cls.from_state(state, parts)
        _try_out(recogniser)
    except ServantError:
        raise
    except Exception as exc:  # an untrusted file: whatever it makes the method trip on
        raise _damaged(path, f"{role}: {type(exc).__name__}: {first_line(exc)[:120]}") from None
    return recogniser


# parameter types a JSON list stands for
SEQUENCES = (tuple, list, collections.abc.Sequence)


def _check_params(cls: type, params: Any, sense: str) -> None:
    """Each parameter must be one the method takes, of the type its `__init__` declares (a
    float may be written as a whole number), and numbers within limits."""
    if not isinstance(params, dict):
        raise ValueError("no parameters")
    hints = typing.get_type_hints(cls.__init__)  # type: ignore[misc]
    for name, value in params.items():
        if name not in hints or name == "return":
            raise ValueError(f"unknown parameter {str(name)[:40]!r}")
        if isinstance(value, list) and typing.get_origin(hints[name]) in SEQUENCES:
            _check_numbers(name, value)  # e.g. softbovw's pyramid grids, (1, 2) in JSON
            continue
        allowed = typing.get_args(hints[name]) or (hints[name],)
        kind = type(value)
        if not (
            kind in allowed
            or (kind is int and float in allowed)
            or value is None
            and type(None) in allowed
        ):
            raise ValueError(f"parameter {name} is {str(value)[:20]!r}")
        if kind in (int, float):
            low, high = PARAM_LIMITS.get(name, GENERIC_LIMIT)
            if name == "rate" and sense in SENSOR_RATE_LIMITS:
                low, high = SENSOR_RATE_LIMITS[sense]
            if not (is_finite_number(value) and low <= value <= high):
                raise ValueError(f"parameter {name} is {value!r}, outside {low:g}–{high:g}")


def _check_numbers(name: str, values: list[Any]) -> None:
    """A short list of numbers within the parameter's limits."""
    low, high = PARAM_LIMITS.get(name, GENERIC_LIMIT)
    if len(values) > 16 or not all(
        type(v) in (int, float) and is_finite_number(v) and low <= v <= high for v in values
    ):
        raise ValueError(f"parameter {name} is {str(values)[:20]!r}")


def _check_scenes(state: dict[str, Any]) -> None:
    scenes = state.get("scenes")
    if (
        not isinstance(scenes, list)
        or len(scenes) < 2
        or not all(isinstance(s, str) and s and s != UNKNOWN for s in scenes)
        or len(set(scenes)) != len(scenes)
    ):
        raise ValueError("its scenes are not a list of two or more distinct names")


# arrays that hold text: the scene and the visit of each training row a method keeps for its
# fold-in, and the place of each row of a head that learns a place's visits apart
TEXT_ARRAYS = {"train_scenes", "train_visits", "mode_scenes"}


def _check_arrays(parts: dict[str, np.ndarray]) -> None:
    """Finite numbers in at most three dimensions (stacked codebooks); text only where a
    method stores it (`TEXT_ARRAYS`), one dimension."""
    for name, array in parts.items():
        if name in TEXT_ARRAYS and array.dtype.kind == "U" and array.ndim == 1:
            continue
        if array.dtype.kind not in "biuf" or array.ndim > 3:
            raise ValueError(f"array {name} is not a table of numbers")
        if array.dtype.kind == "f" and not np.all(np.isfinite(array)):
            raise ValueError(f"array {name} holds NaN or infinity")


def _check_centroids(
    state: dict[str, Any], parts: dict[str, np.ndarray], prefix: str, scenes: list[str]
) -> None:
    """Centres (K, d), one spread (and count) a centre, one of `scenes` (or None) a centre."""
    centres = parts.get(f"{prefix}centres")
    if centres is None:
        raise ValueError(f"no {prefix}centres")
    if centres.ndim != 2 or len(centres) == 0 or centres.shape[1] == 0:
        raise ValueError(f"{prefix}centres of shape {centres.shape}")
    k = len(centres)
    for name in ("spreads", "counts"):
        array = parts.get(f"{prefix}{name}")
        if array is not None and array.shape != (k,):
            raise ValueError(f"{prefix}{name} of shape {array.shape} for {k} centres")
    if f"{prefix}spreads" in parts and not np.all(parts[f"{prefix}spreads"] > 0):
        raise ValueError(f"{prefix}spreads not all above zero")
    owners = state.get("cluster_scene")
    if not isinstance(owners, list) or len(owners) != k:
        raise ValueError(f"{k} centres but {len(owners) if isinstance(owners, list) else 0} owners")
    if not all(o is None or o in scenes for o in owners):
        raise ValueError("its clusters name scenes it does not have")


def _try_out(recogniser: Recogniser) -> None:
    """Recognise one made-up window or picture: a model whose arrays do not fit its method
    fails here, at load time, rather than on the first live window."""
    rng = np.random.default_rng(0)
    if recogniser.sense == "audio":
        rate, seconds = recogniser.rate, recogniser.window_seconds  # type: ignore[attr-defined]
        item: Any = 0.01 * rng.standard_normal((1, int(round(rate * seconds))), dtype=np.float32)
    elif recogniser.sense in SENSOR_RATE_LIMITS:
        rate, seconds = recogniser.rate, recogniser.window_seconds  # type: ignore[attr-defined]
        shape = (int(round(rate * seconds)), len(recogniser.channels))  # type: ignore[attr-defined]
        item = [1.0 + 0.01 * rng.standard_normal(shape, dtype=np.float32)]
    else:
        item = [rng.integers(0, 256, (48, 64, 3), dtype=np.uint8)]
    X = recogniser.featurize(item)
    n_scenes = len(recogniser.scenes_)
    predicted = recogniser.predict(X)
    confidence = np.asarray(recogniser.confidence(X), dtype=float)
    proba = np.asarray(recogniser.predict_proba(X), dtype=float)
    if predicted.shape != (1,) or confidence.shape != (1,) or proba.shape != (1, n_scenes):
        raise ValueError("its arrays do not fit its method")
    if not (np.all(np.isfinite(confidence)) and np.all(np.isfinite(proba))):
        raise ValueError("it gives NaN or infinite confidences")
