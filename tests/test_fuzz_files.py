"""Fuzzing the file boundary: generated corrupt recordings, pictures and model files, given to
the real command line. Every case must end in success or one `servant: error:` line with exit
status 2: no traceback, no hang, nothing damaged; a sample runs in a child process whose peak
memory is measured (issue 13: at most 1 GB for a file under 10 MB).

Cases per run: about 3,300 here (SERVANT_FUZZ_SCALE=10 for a deeper run); the calls are
in-process through `servant_core.cli.main`, with the paper's small models, so the run takes a
few minutes.
"""

from __future__ import annotations

import io
import json
import os
import zlib
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import soundfile as sf
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from servant_core.audio import write_wav
from servant_core.storage import atomic_save_npz
from tests.cli_harness import (
    ONE_GB,
    assert_clear,
    assert_refused,
    run_cli,
    run_cli_subprocess,
    zip_bomb,
)
from tests.conftest import tone
from tests.test_fuzz_settings import beyond_floats

SCALE = float(os.environ.get("SERVANT_FUZZ_SCALE", "1"))


def fuzz(examples: int) -> Any:
    return settings(
        max_examples=max(1, int(examples * SCALE)),
        deadline=None,
        database=None,
        suppress_health_check=list(HealthCheck),
    )


def encoded_audio(signal: np.ndarray, rate: int, fmt: str, subtype: str | None = None) -> bytes:
    buffer = io.BytesIO()
    sf.write(buffer, signal, rate, format=fmt, subtype=subtype)
    return buffer.getvalue()


def encoded_picture(suffix: str, image: np.ndarray, params: list[int] | None = None) -> bytes:
    ok, data = cv2.imencode(suffix, image, params or [])
    assert ok
    return data.tobytes()


class Workspace:
    """Good models and good files to corrupt, made once per module."""

    def __init__(self, root: Path) -> None:
        self.root = root
        lib = root / "lib"
        for k, scene in enumerate(("cafe", "gym")):
            (lib / scene).mkdir(parents=True)
            for i in range(2):
                signal = tone(300 + 900 * k + 20 * i, 1.0, 8000)
                write_wav(lib / scene / f"r{i}.wav", signal, 8000)
                image = np.full((16, 16, 3), 40 + 150 * k + 5 * i, np.uint8)
                cv2.imwrite(str(lib / scene / f"p{i}.png"), image)
        self.library = lib
        self.model = root / "model.npz"
        small = ["--rate", "8000", "--window", "0.5"]
        paper = ["--audio-method", "paper", "--image-method", "paper"]
        assert run_cli("train", str(lib), "-o", str(self.model), *small, *paper).code == 0
        self.good_model = self.model.read_bytes()
        self.fresh_model = root / "fresh.npz"
        assert run_cli("train", str(lib), "-o", str(self.fresh_model), *small).code == 0
        self.good_wav = lib / "cafe" / "r0.wav"
        self.good_png = lib / "cafe" / "p0.png"
        rng = np.random.default_rng(0)
        signal = np.tile(tone(440, 0.4, 8000), 3) + 0.01 * rng.standard_normal(9600, np.float32)
        stereo = np.stack([signal, signal[::-1]], axis=1)
        self.audio = {
            ".wav": encoded_audio(signal, 8000, "WAV", "PCM_16"),
            ".flac": encoded_audio(stereo, 8000, "FLAC"),
            ".mp3": encoded_audio(signal, 8000, "MP3"),
            ".ogg": encoded_audio(signal, 8000, "OGG"),
        }
        self.float_wav = encoded_audio(signal, 8000, "WAV", "FLOAT")
        image = rng.integers(0, 256, (24, 32, 3), dtype=np.uint8)
        self.pictures = {
            ".png": encoded_picture(".png", image),
            ".jpg": encoded_picture(".jpg", image),
            ".jpeg": encoded_picture(".jpg", image, [cv2.IMWRITE_JPEG_PROGRESSIVE, 1]),
        }
        self.grey_png = encoded_picture(".png", image[:, :, 0])

    def case(self, name: str, data: bytes) -> Path:
        path = self.root / name
        path.write_bytes(data)
        return path

    def predict(self, *argv: str) -> Any:
        outcome = run_cli("predict", str(self.model), *argv)
        assert_clear(outcome)
        return outcome


@pytest.fixture(scope="module")
def ws(tmp_path_factory: pytest.TempPathFactory) -> Workspace:
    return Workspace(tmp_path_factory.mktemp("fuzz"))


@pytest.fixture(scope="module", autouse=True)
def good_model_unchanged(ws: Workspace):
    """Nothing the fuzzing does may touch the model it reads."""
    yield
    assert ws.model.read_bytes() == ws.good_model


# Byte-level corruption: a few bytes changed (often in the header), and/or the file cut short.
flips = st.lists(
    st.tuples(st.one_of(st.integers(0, 127), st.integers(0, 1 << 20)), st.integers(0, 255)),
    max_size=8,
)
cut = st.one_of(st.none(), st.integers(0, 1 << 20))


def corrupt(data: bytes, changes: list[tuple[int, int]], length: int | None) -> bytes:
    out = bytearray(data)
    for at, value in changes:
        out[at % len(out)] = value
    return bytes(out[: length % (len(out) + 1)] if length is not None else out)


# Recordings (issue 13 item 4).


@fuzz(900)
@given(suffix=st.sampled_from([".wav", ".flac", ".mp3", ".ogg"]), changes=flips, length=cut)
def test_fuzz_corrupt_recordings(ws: Workspace, suffix: str, changes, length) -> None:
    path = ws.case(f"audio{suffix}", corrupt(ws.audio[suffix], changes, length))
    ws.predict("--audio", str(path))


@fuzz(400)
@given(
    channels=st.integers(0, 0xFFFF),
    rate=st.one_of(st.integers(0, 0xFFFFFFFF), st.sampled_from([1, 7999, 8000, 192000, 192001])),
    block=st.one_of(st.none(), st.integers(0, 0xFFFF)),
    bits=st.one_of(st.none(), st.sampled_from([0, 1, 7, 8, 12, 16, 24, 32, 64, 0xFFFF])),
    data_size=st.one_of(st.none(), st.integers(0, 0xFFFFFFFF)),
)
def test_fuzz_wav_header_fields(ws: Workspace, channels, rate, block, bits, data_size) -> None:
    """The RIFF fmt fields a damaged header gets wrong: a 1 Hz rate once asked for 5.6 GB."""
    data = bytearray(ws.audio[".wav"])
    data[22:24] = channels.to_bytes(2, "little")
    data[24:28] = rate.to_bytes(4, "little")
    if block is not None:
        data[32:34] = block.to_bytes(2, "little")
    if bits is not None:
        data[34:36] = bits.to_bytes(2, "little")
    if data_size is not None:
        data[40:44] = data_size.to_bytes(4, "little")
    outcome = ws.predict("--audio", str(ws.case("header.wav", bytes(data))))
    if not 8000 <= rate <= 192000:
        assert outcome.code == 2


@fuzz(200)
@given(
    samples=st.lists(st.integers(0, 9599), min_size=1, max_size=5),
    value=st.sampled_from([np.nan, np.inf, -np.inf]),
)
def test_fuzz_nan_samples_skip_their_windows(ws: Workspace, samples, value) -> None:
    """Each window a sample that is no number falls in is skipped in one line; with none
    left, one error line."""
    data = bytearray(ws.float_wav)
    start = data.find(b"data") + 8
    for i in samples:
        data[start + 4 * i : start + 4 * i + 4] = np.float32(value).tobytes()
    outcome = ws.predict("--audio", str(ws.case("nan.wav", bytes(data))))
    if outcome.code == 0:  # (a sample in the remainder after the last window is never read)
        assert "Acoustic window" in outcome.out and "nan" not in outcome.out.lower()
        assert_clear(outcome)
    else:
        assert_refused(outcome, "finite numbers")


# Pictures (issue 13 item 5).


@fuzz(700)
@given(suffix=st.sampled_from([".png", ".jpg", ".jpeg"]), changes=flips, length=cut)
def test_fuzz_corrupt_pictures(ws: Workspace, suffix: str, changes, length) -> None:
    path = ws.case(f"picture{suffix}", corrupt(ws.pictures[suffix], changes, length))
    ws.predict("--image", str(path))


def png_claiming(data: bytes, width: int, height: int) -> bytes:
    out = bytearray(data)
    out[16:20], out[20:24] = width.to_bytes(4, "big"), height.to_bytes(4, "big")
    out[29:33] = zlib.crc32(bytes(out[12:29])).to_bytes(4, "big")
    return bytes(out)


def jpeg_claiming(data: bytes, width: int, height: int) -> bytes:
    out = bytearray(data)
    at = out.find(b"\xff\xc0")
    if at < 0:
        at = out.find(b"\xff\xc2")
    out[at + 5 : at + 7], out[at + 7 : at + 9] = height.to_bytes(2, "big"), width.to_bytes(2, "big")
    return bytes(out)


@fuzz(400)
@given(
    kind=st.sampled_from(["png", "grey", "jpg", "jpeg"]),
    width=st.one_of(st.integers(0, 0xFFFF), st.integers(0, 0xFFFFFFFF)),
    height=st.one_of(st.integers(0, 0xFFFF), st.integers(0, 0xFFFFFFFF)),
)
def test_fuzz_picture_sizes_claimed_by_the_header(ws: Workspace, kind, width, height) -> None:
    """A header may claim any size; over 50 megapixels is refused before decoding."""
    if kind in ("png", "grey"):
        data = png_claiming(ws.pictures[".png"] if kind == "png" else ws.grey_png, width, height)
    else:
        width, height = width & 0xFFFF, height & 0xFFFF
        data = jpeg_claiming(ws.pictures["." + kind], width, height)
    outcome = ws.predict("--image", str(ws.case("claims.png", data)))
    if width * height > 50_000_000:
        assert_refused(outcome, "megapixels")


@fuzz(200)
@given(data=st.binary(max_size=4096), suffix=st.sampled_from([".wav", ".mp3", ".png", ".jpg"]))
def test_fuzz_random_bytes(ws: Workspace, data: bytes, suffix: str) -> None:
    path = ws.case(f"random{suffix}", data)
    option = "--audio" if suffix in (".wav", ".mp3") else "--image"
    ws.predict(option, str(path))


# Model files (issue 13 item 3).


def model_arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as npz:
        return {name: npz[name] for name in npz.files}


def header_paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    paths = [prefix]
    if isinstance(node, dict):
        for key, value in node.items():
            paths += header_paths(value, (*prefix, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            paths += header_paths(value, (*prefix, i))
    return paths


json_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**70), 2**70)
    | beyond_floats
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8)
    | st.sampled_from(["paper", "audio", "image", "servant-model", "<unknown>", "cafe"]),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4)
    ),
    max_leaves=12,
)


def set_path(root: Any, path: tuple, value: Any, delete: bool) -> Any:
    if not path:
        return value
    node = root
    for key in path[:-1]:
        node = node[key]
    if delete and isinstance(node, dict):
        del node[path[-1]]
    else:
        node[path[-1]] = value
    return root


def mutated_model(ws: Workspace, source: Path, change) -> Path:
    arrays = model_arrays(source)
    change(arrays)
    path = ws.root / "mutated.npz"
    atomic_save_npz(path, arrays)
    return path


def predict_both(ws: Workspace, model: Path) -> None:
    outcome = run_cli(
        "predict", str(model), "--audio", str(ws.good_wav), "--image", str(ws.good_png)
    )
    assert_clear(outcome)
    assert "nan" not in outcome.out


@fuzz(500)
@given(pick=st.integers(0, 10**6), value=json_values, delete=st.booleans(), fresh=st.booleans())
def test_fuzz_model_headers(ws: Workspace, pick: int, value, delete: bool, fresh: bool) -> None:
    source = ws.fresh_model if fresh else ws.model

    def change(arrays: dict[str, np.ndarray]) -> None:
        header = json.loads(str(arrays["header"]))
        paths = header_paths(header)
        header = set_path(header, paths[pick % len(paths)], value, delete)
        arrays["header"] = np.array(json.dumps(header))

    predict_both(ws, mutated_model(ws, source, change))


transforms = st.sampled_from(
    [
        "drop",
        "nan",
        "inf",
        "row",
        "column",
        "flat",
        "transpose",
        "int",
        "complex",
        "bool",
        "scalar",
        "empty",
        "huge",
        "negative",
        "text",
    ]
)


def transform(array: np.ndarray, how: str) -> np.ndarray | None:
    a = np.array(array, copy=True)
    if how == "drop":
        return None
    if how in ("nan", "inf") and a.dtype.kind == "f" and a.size:
        a.flat[0] = np.nan if how == "nan" else np.inf
        return a
    if how == "row":
        return np.concatenate([a, a[:1]]) if a.ndim else a
    if how == "column":
        return a[..., :-1] if a.ndim > 1 else a[:-1] if a.ndim else a
    if how == "flat":
        return a.ravel()
    if how == "transpose":
        return a.T
    if how == "int":
        return a.astype(np.int64) if a.dtype.kind == "f" else a
    if how == "complex":
        return a.astype(np.complex64) if a.dtype.kind in "fiu" else a
    if how == "bool":
        return a.astype(bool) if a.dtype.kind in "fiu" else a
    if how == "scalar":
        return np.array(3.0)
    if how == "empty":
        return np.zeros((0,) + a.shape[1:], a.dtype)
    if how == "huge":
        return np.full(a.shape, 1e38, np.float32) if a.dtype.kind == "f" else a
    if how == "negative":
        return -a if a.dtype.kind in "fi" else a
    return np.array(["x"] * max(a.size, 1))


@fuzz(400)
@given(pick=st.integers(0, 100), how=transforms, fresh=st.booleans())
def test_fuzz_model_arrays(ws: Workspace, pick: int, how: str, fresh: bool) -> None:
    source = ws.fresh_model if fresh else ws.model

    def change(arrays: dict[str, np.ndarray]) -> None:
        names = sorted(k for k in arrays if k != "header")
        name = names[pick % len(names)]
        new = transform(arrays[name], how)
        if new is None:
            del arrays[name]
        else:
            arrays[name] = new

    predict_both(ws, mutated_model(ws, source, change))


@fuzz(300)
@given(changes=flips, length=cut, declared=st.one_of(st.none(), st.integers(0, 0xFFFFFFFF)))
def test_fuzz_model_bytes_and_declared_sizes(ws: Workspace, changes, length, declared) -> None:
    data = bytearray(ws.good_model)
    if declared is not None:  # the central directory's uncompressed size of one member
        at = data.find(b"PK\x01\x02", (declared * 7919) % len(data))
        at = at if at >= 0 else data.find(b"PK\x01\x02")
        data[at + 24 : at + 28] = declared.to_bytes(4, "little")
    path = ws.case("bytes.npz", corrupt(bytes(data), changes, length))
    predict_both(ws, path)


# Training over a library with one damaged file: the old model stays as it was.


@fuzz(60)
@given(
    kind=st.sampled_from([".wav", ".flac", ".mp3", ".png", ".jpg"]),
    changes=flips,
    length=cut,
    skip=st.booleans(),
)
def test_fuzz_train_keeps_the_old_model(ws: Workspace, kind, changes, length, skip) -> None:
    base = ws.audio.get(kind) or ws.pictures[kind]
    bad = ws.library / "gym" / f"zz-bad{kind}"
    bad.write_bytes(corrupt(base, changes, length))
    target = ws.root / "kept.npz"
    target.write_bytes(ws.good_model)
    try:
        argv = ["train", str(ws.library), "-o", str(target), "--rate", "8000", "--window", "0.5"]
        argv += ["--audio-method", "paper", "--image-method", "paper"]
        outcome = run_cli(*argv, *(["--skip-bad"] if skip else []))
    finally:
        bad.unlink()
    assert_clear(outcome)
    if outcome.code != 0:
        assert target.read_bytes() == ws.good_model
    assert not [p for p in ws.root.iterdir() if p.name.endswith(".tmp")]


# A sample in a child process: the real console script, its peak memory measured.


@pytest.mark.devices
def test_worst_cases_in_a_child_process_stay_under_a_gigabyte(ws: Workspace) -> None:
    wav_1hz = bytearray(ws.audio[".wav"])
    wav_1hz[24:28] = (1).to_bytes(4, "little")
    rng = np.random.default_rng(7)
    cases = [
        ("--audio", ws.case("one-hz.wav", bytes(wav_1hz))),
        ("--audio", ws.case("garbled.wav", corrupt(ws.audio[".wav"], [(25, 0), (26, 0)], None))),
        ("--image", ws.case("giga.png", png_claiming(ws.pictures[".png"], 40000, 40000))),
        ("--image", ws.case("big.png", png_claiming(ws.pictures[".png"], 9000, 9000))),
        (
            "--image",
            ws.case(
                "noise.jpg",
                corrupt(ws.pictures[".jpg"], [(int(i), 0) for i in rng.integers(0, 600, 8)], None),
            ),
        ),
    ]
    outcomes = [run_cli_subprocess("predict", str(ws.model), option, str(p)) for option, p in cases]
    outcomes.append(
        run_cli_subprocess(
            "predict", str(zip_bomb(ws.root / "bomb.npz")), "--image", str(ws.good_png)
        )
    )
    for outcome in outcomes:
        assert_clear(outcome, seconds=60)
        assert outcome.peak_mb < ONE_GB / 1024**2, outcome
    print("peak MB per worst case:", [round(o.peak_mb) for o in outcomes])
