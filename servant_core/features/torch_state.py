"""A PyTorch state dict (names → tensors) read into numpy, without torch and without unpickling.

Both `.pth` layouts are read: torch's legacy stream (before 1.6) and its zip archive. The pickle's
opcodes (`pickletools.genops`, which only decodes them) drive a small stack machine that knows
strings, numbers, tuples, dicts, an `OrderedDict`, a storage reference and `_rebuild_tensor_v2`,
and refuses anything else before anything is built. Nothing is imported or called by name; each
tensor is a bounds-checked view of its storage's bytes, then copied.
"""

from __future__ import annotations

import io
import pickletools
import struct
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, cast

import numpy as np

LEGACY_MAGIC = 0x1950A86A20F9469CFC6C
LEGACY_VERSION = 1001
STORAGE_DTYPES: dict[str, np.dtype] = {
    "torch FloatStorage": np.dtype("<f4"),
    "torch DoubleStorage": np.dtype("<f8"),
    "torch HalfStorage": np.dtype("<f2"),
    "torch LongStorage": np.dtype("<i8"),
    "torch IntStorage": np.dtype("<i4"),
    "torch ShortStorage": np.dtype("<i2"),
    "torch CharStorage": np.dtype("i1"),
    "torch ByteStorage": np.dtype("u1"),
    "torch BoolStorage": np.dtype("?"),
}
ORDERED_DICT = "collections OrderedDict"
REBUILD_TENSOR = "torch._utils _rebuild_tensor_v2"
REBUILD_PARAMETER = "torch._utils _rebuild_parameter"
ALLOWED_GLOBALS = {ORDERED_DICT, REBUILD_TENSOR, REBUILD_PARAMETER, *STORAGE_DTYPES}
# the opcodes whose argument is the value they push: numbers, strings, bytes
VALUE_OPCODES = {
    "INT", "BININT", "BININT1", "BININT2", "LONG", "LONG1", "LONG4", "FLOAT", "BINFLOAT",
    "BINUNICODE", "SHORT_BINUNICODE", "BINUNICODE8", "UNICODE", "STRING", "BINSTRING",
    "SHORT_BINSTRING", "BINBYTES", "SHORT_BINBYTES", "BINBYTES8",
}  # fmt: skip
# with them, the opcodes that build tuples, lists and dicts, keep and fetch values in the memo and
# mark the stack: nothing else a state dict of tensors needs (no INST, OBJ, NEWOBJ, EXT*: those
# make objects of any class)
DATA_OPCODES = VALUE_OPCODES | {
    "PROTO", "FRAME", "STOP", "MARK", "POP", "POP_MARK", "DUP", "NONE", "NEWTRUE", "NEWFALSE",
    "EMPTY_TUPLE", "TUPLE", "TUPLE1", "TUPLE2", "TUPLE3", "EMPTY_LIST", "APPEND", "APPENDS",
    "LIST", "EMPTY_DICT", "DICT", "SETITEM", "SETITEMS",
    "PUT", "BINPUT", "LONG_BINPUT", "MEMOIZE", "GET", "BINGET", "LONG_BINGET",
}  # fmt: skip
CALL_OPCODES = {"GLOBAL", "STACK_GLOBAL", "REDUCE", "BUILD", "BINPERSID", "PERSID"}
MAX_ELEMENTS = 1 << 31  # a storage of more than 2 G elements is no picture network


class TorchStateError(ValueError):
    """The file is not a state dict of tensors this reader accepts; nothing in it was run."""


@dataclass(frozen=True)
class Global:
    """A name the pickle asked for, allowed but never imported."""

    name: str


@dataclass(frozen=True)
class StorageRef:
    key: str
    dtype: np.dtype
    elements: int


@dataclass(frozen=True)
class TensorRef:
    storage: StorageRef
    offset: int
    shape: tuple[int, ...]
    stride: tuple[int, ...]


class _Mark:
    pass


MARK = _Mark()


def _pop_mark(stack: list[Any]) -> list[Any]:
    for i in range(len(stack) - 1, -1, -1):
        if stack[i] is MARK:
            items = stack[i + 1 :]
            del stack[i:]
            return items
    raise TorchStateError("a pickle mark is missing")


def _int_tuple(value: Any, what: str) -> tuple[int, ...]:
    if not isinstance(value, tuple) or not all(
        isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in value
    ):
        raise TorchStateError(f"a tensor's {what} is not a tuple of counts: {value!r}")
    return value


def _storage(pid: Any) -> StorageRef:
    """A storage reference from a persistent id: ('storage', type, key, location, elements[,
    view]); a view of another storage (the legacy format's sixth element) is refused."""
    if not (isinstance(pid, tuple) and len(pid) in (5, 6) and pid[0] == "storage"):
        raise TorchStateError(f"a persistent id that is not a storage: {pid!r}")
    kind, key, elements = pid[1], pid[2], pid[4]
    if not isinstance(kind, Global) or kind.name not in STORAGE_DTYPES:
        raise TorchStateError(f"a storage of an unknown type: {kind!r}")
    if len(pid) == 6 and pid[5] is not None:
        raise TorchStateError("a storage view (legacy shared storage) is not supported")
    if not isinstance(key, str) or not isinstance(elements, int) or not 0 <= elements:
        raise TorchStateError(f"a storage with a bad key or size: {pid!r}")
    if elements > MAX_ELEMENTS:
        raise TorchStateError(f"a storage of {elements} elements is too large")
    return StorageRef(key, STORAGE_DTYPES[kind.name], elements)


def _rebuild(function: Global, args: Any) -> Any:
    """What REDUCE makes of an allowed callable and its arguments, without calling anything."""
    if not isinstance(args, tuple):
        raise TorchStateError(f"{function.name} called with {type(args).__name__}, not a tuple")
    if function.name == ORDERED_DICT:
        if args:
            raise TorchStateError("an OrderedDict built from arguments")
        return {}
    if function.name == REBUILD_TENSOR:
        # (storage, offset, size, stride, requires_grad, backward_hooks[, metadata])
        if len(args) not in (6, 7) or not isinstance(args[0], StorageRef):
            raise TorchStateError("_rebuild_tensor_v2 with arguments it never has")
        offset = args[1]
        if not isinstance(offset, int) or offset < 0:
            raise TorchStateError(f"a tensor's offset is {offset!r}")
        shape, stride = _int_tuple(args[2], "size"), _int_tuple(args[3], "stride")
        if len(shape) != len(stride):
            raise TorchStateError("a tensor's size and stride differ in length")
        return TensorRef(args[0], offset, shape, stride)
    if function.name == REBUILD_PARAMETER:  # (data, requires_grad, backward_hooks)
        if len(args) != 3 or not isinstance(args[0], TensorRef):
            raise TorchStateError("_rebuild_parameter with arguments it never has")
        return args[0]
    raise TorchStateError(f"{function.name} cannot be called")  # a storage type: never called


def read_pickle(stream: IO[bytes], persistent: Callable[[Any], Any] = _storage) -> Any:
    """The value of the next pickle in `stream`, built only from plain data, allowed names
    (`ALLOWED_GLOBALS`, as `Global`), storage references (`persistent`) and tensor references;
    TorchStateError for any other opcode or name, raised before the pickle is done."""
    stack: list[Any] = []
    memo: dict[int, Any] = {}
    try:
        for opcode, decoded, _ in pickletools.genops(stream):
            name, arg = opcode.name, cast(Any, decoded)
            if name not in DATA_OPCODES and name not in CALL_OPCODES:
                raise TorchStateError(f"pickle opcode {name} is not allowed in a state dict")
            if name == "STOP":
                break
            if name in ("PROTO", "FRAME"):
                continue
            handled = (
                _stack_op(name, arg, stack, memo)
                or _collection_op(name, stack)
                or _call_op(name, arg, stack, persistent)
            )
            if not handled:  # pragma: no cover - every allowed opcode has a branch
                raise TorchStateError(f"pickle opcode {name} is not handled")
        else:
            raise TorchStateError("the pickle ends without STOP")
    except (IndexError, KeyError, TypeError) as exc:
        raise TorchStateError(f"a malformed pickle ({type(exc).__name__}: {exc})") from None
    if len(stack) != 1:
        raise TorchStateError("the pickle leaves no single value")
    return stack[0]


def _stack_op(name: str, arg: Any, stack: list[Any], memo: dict[int, Any]) -> bool:
    """Runs a stack opcode (marks, POP, DUP), a constant or value that it pushes, or a memo
    opcode (PUT, GET); False for any other opcode, with `stack` and `memo` untouched."""
    if name == "MARK":
        stack.append(MARK)
    elif name == "POP":
        stack.pop()
    elif name == "POP_MARK":
        _pop_mark(stack)
    elif name == "DUP":
        stack.append(stack[-1])
    elif name == "NONE":
        stack.append(None)
    elif name in ("NEWTRUE", "NEWFALSE"):
        stack.append(name == "NEWTRUE")
    elif name in VALUE_OPCODES:
        stack.append(arg)
    elif name in ("PUT", "BINPUT", "LONG_BINPUT"):
        memo[int(arg)] = stack[-1]
    elif name == "MEMOIZE":
        memo[len(memo)] = stack[-1]
    elif name in ("GET", "BINGET", "LONG_BINGET"):
        stack.append(memo[int(arg)])
    else:
        return False
    return True


def _collection_op(name: str, stack: list[Any]) -> bool:
    """Runs an opcode that builds a tuple, or builds or fills a list or a dict (keys only names
    or numbers); False for any other opcode, with `stack` untouched."""
    if name == "EMPTY_TUPLE":
        stack.append(())
    elif name in ("TUPLE1", "TUPLE2", "TUPLE3"):
        n = int(name[-1])
        grouped = tuple(stack[-n:])
        del stack[-n:]
        stack.append(grouped)
    elif name == "TUPLE":
        stack.append(tuple(_pop_mark(stack)))
    elif name == "EMPTY_LIST":
        stack.append([])
    elif name == "LIST":
        stack.append(_pop_mark(stack))
    elif name == "APPEND":
        value = stack.pop()
        _container(stack[-1], list).append(value)
    elif name == "APPENDS":
        items = _pop_mark(stack)
        _container(stack[-1], list).extend(items)
    elif name == "EMPTY_DICT":
        stack.append({})
    elif name == "DICT":
        items = _pop_mark(stack)
        stack.append(dict(zip(items[::2], items[1::2], strict=True)))
    elif name == "SETITEM":
        value, key = stack.pop(), stack.pop()
        _container(stack[-1], dict)[_key(key)] = value
    elif name == "SETITEMS":
        items = _pop_mark(stack)
        target = _container(stack[-1], dict)
        for key, value in zip(items[::2], items[1::2], strict=True):
            target[_key(key)] = value
    else:
        return False
    return True


def _call_op(name: str, arg: Any, stack: list[Any], persistent: Callable[[Any], Any]) -> bool:
    """Runs an opcode that names or calls something, without importing or calling anything: an
    allowed name becomes a `Global`, REDUCE a value `_rebuild` makes, a persistent id what
    `persistent` makes of it; any other name or call is refused. False for any other opcode."""
    if name in ("GLOBAL", "STACK_GLOBAL"):
        stack.append(_global(name, arg, stack))
    elif name == "REDUCE":
        args, function = stack.pop(), stack.pop()
        if not isinstance(function, Global):
            raise TorchStateError(f"the pickle calls {type(function).__name__}")
        stack.append(_rebuild(function, args))
    elif name == "BUILD":
        state = stack.pop()
        # an OrderedDict's attributes (a module's `_metadata`: versions, not tensors)
        if not isinstance(stack[-1], dict) or not isinstance(state, (dict, type(None))):
            raise TorchStateError("the pickle sets the state of something not a dict")
    elif name in ("BINPERSID", "PERSID"):
        stack.append(persistent(stack.pop() if name == "BINPERSID" else arg))
    else:
        return False
    return True


def _global(name: str, arg: Any, stack: list[Any]) -> Global:
    """The name GLOBAL (its argument) or STACK_GLOBAL (module and attribute popped off `stack`)
    asks for, if `ALLOWED_GLOBALS` has it; TorchStateError otherwise."""
    if name == "GLOBAL":
        qualified = str(arg)
    else:
        attribute, module = stack.pop(), stack.pop()
        qualified = f"{module} {attribute}"
    if qualified not in ALLOWED_GLOBALS:
        raise TorchStateError(
            f"the pickle asks for {qualified.replace(' ', '.')}, which a state dict "
            "of tensors never does; refused, nothing was run"
        )
    return Global(qualified)


def _container(value: Any, kind: type) -> Any:
    if not isinstance(value, kind):
        raise TorchStateError(f"the pickle adds items to a {type(value).__name__}")
    return value


def _key(key: Any) -> Any:
    if not isinstance(key, (str, int)):
        raise TorchStateError(f"a dict key that is not a name: {type(key).__name__}")
    return key


def _tensor(ref: TensorRef, data: bytes) -> np.ndarray:
    """The tensor `ref` views in its storage's `data`, bounds-checked, as its own array."""
    storage = np.frombuffer(data, dtype=ref.storage.dtype)
    if len(storage) < ref.storage.elements:
        raise TorchStateError(f"storage {ref.storage.key} is shorter than it says")
    if any(n == 0 for n in ref.shape):
        return np.zeros(ref.shape, dtype=ref.storage.dtype.newbyteorder("="))
    last = ref.offset + sum((n - 1) * s for n, s in zip(ref.shape, ref.stride, strict=True))
    if last >= ref.storage.elements:
        raise TorchStateError(f"a tensor reaches past the end of storage {ref.storage.key}")
    itemsize = ref.storage.dtype.itemsize
    view = np.lib.stride_tricks.as_strided(
        storage[ref.offset :],
        shape=ref.shape,
        strides=tuple(s * itemsize for s in ref.stride),
        writeable=False,
    )
    return np.array(view, dtype=ref.storage.dtype.newbyteorder("="))


def _tensors(state: Any, storages: dict[str, bytes]) -> dict[str, np.ndarray]:
    if not isinstance(state, dict):
        raise TorchStateError(f"the file holds a {type(state).__name__}, not a state dict")
    tensors = {}
    for name, ref in state.items():
        if not isinstance(name, str) or not isinstance(ref, TensorRef):
            raise TorchStateError(f"entry {name!r} is not a tensor")
        if ref.storage.key not in storages:
            raise TorchStateError(f"storage {ref.storage.key} is missing")
        tensors[name] = _tensor(ref, storages[ref.storage.key])
    return tensors


def _read_legacy(stream: IO[bytes]) -> dict[str, np.ndarray]:
    if read_pickle(stream) != LEGACY_MAGIC:
        raise TorchStateError("not a PyTorch file (no magic number)")
    if read_pickle(stream) != LEGACY_VERSION:
        raise TorchStateError("a PyTorch file of an unknown legacy version")
    info = read_pickle(stream)
    if not isinstance(info, dict) or info.get("little_endian") is not True:
        raise TorchStateError("a PyTorch file written on a big-endian machine")
    refs: dict[str, StorageRef] = {}

    def remember(pid: Any) -> StorageRef:
        ref = _storage(pid)
        if refs.setdefault(ref.key, ref) != ref:
            raise TorchStateError(f"storage {ref.key} is named with two sizes")
        return ref

    state = read_pickle(stream, remember)
    keys = read_pickle(stream)
    if not isinstance(keys, list) or not all(isinstance(k, str) for k in keys):
        raise TorchStateError("the list of storages is not a list of names")
    storages: dict[str, bytes] = {}
    for key in keys:
        if key not in refs:
            raise TorchStateError(f"storage {key} is stored but never used")
        count = stream.read(8)
        if len(count) != 8:
            raise TorchStateError(f"the file ends before storage {key}")
        (elements,) = struct.unpack("<q", count)
        if elements != refs[key].elements:
            raise TorchStateError(
                f"storage {key} holds {elements} elements, not {refs[key].elements}"
            )
        size = elements * refs[key].dtype.itemsize
        data = stream.read(size)
        if len(data) != size:
            raise TorchStateError(f"the file ends inside storage {key}")
        storages[key] = data
    return _tensors(state, storages)


def _read_zip(archive: zipfile.ZipFile) -> dict[str, np.ndarray]:
    pickles = [n for n in archive.namelist() if n.endswith("/data.pkl") and n.count("/") == 1]
    if len(pickles) != 1:
        raise TorchStateError("a zip that is not one PyTorch archive (no single data.pkl)")
    folder = pickles[0][: -len("data.pkl")]
    refs: dict[str, StorageRef] = {}

    def remember(pid: Any) -> StorageRef:
        ref = _storage(pid)
        refs[ref.key] = ref
        return ref

    with archive.open(pickles[0]) as pkl:
        state = read_pickle(io.BytesIO(pkl.read()), remember)
    storages = {}
    for key, ref in refs.items():
        member = f"{folder}data/{key}"
        info = archive.getinfo(member) if member in archive.namelist() else None
        if info is None or info.file_size < ref.elements * ref.dtype.itemsize:
            raise TorchStateError(f"storage {key} is missing or short in the archive")
        storages[key] = archive.read(member)
    return _tensors(state, storages)


def read_state_dict(path: str | Path) -> dict[str, np.ndarray]:
    """Every tensor of the state dict saved in `path` (either layout), by name, as numpy
    arrays; TorchStateError if the file is anything else or asks for anything else."""
    path = Path(path)
    if zipfile.is_zipfile(path):
        with zipfile.ZipFile(path) as archive:
            return _read_zip(archive)
    with path.open("rb") as stream:
        return _read_legacy(stream)
