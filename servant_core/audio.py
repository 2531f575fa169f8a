"""Audio files: read any rate or channel count, mix to mono, resample, cut into windows."""

from __future__ import annotations

import os
import stat
from fractions import Fraction
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import soundfile as sf

from servant_core.errors import ServantError

AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3")
DEFAULT_RATE = 44100
DEFAULT_WINDOW_SECONDS = 5.0
# What a recording or a model may claim. Real recordings are 8 kHz (telephone) to 192 kHz
# (studio); a header outside that is damaged. Ten minutes keeps the decoded mono copy and its
# resampled copy of a 192 kHz file well under a gigabyte; longer recordings can be cut up.
MIN_RATE = 8000
MAX_RATE = 192000
MAX_CHANNELS = 16
MAX_RECORDING_SECONDS = 600.0
MIN_WINDOW_SECONDS = 0.5
MAX_WINDOW_SECONDS = 60.0
BLOCK_FRAMES = 1 << 16


def to_mono(samples: np.ndarray) -> np.ndarray:
    """Average the channels of a (frames, channels) array; a 1-D array is already mono."""
    samples = np.asarray(samples, dtype=np.float32)
    return samples if samples.ndim == 1 else samples.mean(axis=1, dtype=np.float32)


def resample(signal: np.ndarray, rate_in: int, rate_out: int) -> np.ndarray:
    """Polyphase resampling (anti-aliased) from `rate_in` to `rate_out`."""
    if rate_in == rate_out:
        return np.asarray(signal, dtype=np.float32)
    ratio = Fraction(rate_out, rate_in)
    from scipy.signal import resample_poly  # scipy.signal takes a second to import: on use

    out = resample_poly(signal, ratio.numerator, ratio.denominator)
    return out.astype(np.float32, copy=False)


def read_audio(path: str | Path, rate: int = DEFAULT_RATE) -> np.ndarray:
    """Read an audio file as mono float32 at `rate`; a bad file raises one clear ServantError.

    The header is checked before anything is decoded (a damaged header claiming 1 Hz or a
    million channels would otherwise ask for gigabytes), and the file is decoded in blocks, so
    memory holds one mono copy at the file's rate and one at `rate`.
    """
    path = Path(path)
    with open_regular_file(path, "audio file") as handle:
        info = _checked_info(path, handle)
        handle.seek(0)
        mono = _decode_mono(path, handle, info)
    return resample(mono, info.samplerate, rate)


def open_regular_file(path: Path, what: str) -> BinaryIO:
    """Open a file for reading in Python (any file name works, even one that is not UTF-8);
    a missing file, a folder, a FIFO or a device is refused without blocking on it."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            raise ServantError(f"{path}: not a regular file; give an {what}")
        return open(path, "rb")
    except FileNotFoundError:
        raise ServantError(f"{path}: no such file; check the path") from None
    except OSError as exc:
        raise ServantError(f"{path}: cannot open the {what} ({os_reason(exc)})") from None


def os_reason(exc: OSError) -> str:
    """The operating system's short reason ("Permission denied"), not the whole repr."""
    return exc.strerror or type(exc).__name__


def _not_readable(path: Path, reason: str) -> ServantError:
    return ServantError(f"{path}: not a readable audio file ({reason}); use WAV, FLAC, OGG or MP3")


def _checked_info(path: Path, handle: BinaryIO) -> Any:
    try:
        info = sf.info(handle)
    except (sf.LibsndfileError, RuntimeError, ValueError, TypeError) as exc:
        raise _not_readable(path, first_line(exc)) from None
    if not MIN_RATE <= info.samplerate <= MAX_RATE:
        raise ServantError(
            f"{path}: sample rate {info.samplerate} Hz is outside {MIN_RATE}–{MAX_RATE} Hz "
            "(a damaged header?); re-record or convert the file"
        )
    if not 1 <= info.channels <= MAX_CHANNELS:
        raise ServantError(
            f"{path}: {info.channels} channels is more than {MAX_CHANNELS} (a damaged header?); "
            "convert the file to mono or stereo"
        )
    if info.frames > MAX_RECORDING_SECONDS * info.samplerate:
        raise _too_long(path)
    return info


def _too_long(path: Path) -> ServantError:
    return ServantError(
        f"{path}: longer than {MAX_RECORDING_SECONDS / 60:g} minutes; "
        "cut it into shorter recordings"
    )


def _decode_mono(path: Path, handle: BinaryIO, info: Any) -> np.ndarray:
    """Decode block by block into one mono array sized from the header (a list of blocks and
    their concatenation would hold the recording twice); a header that under-states the
    length still gets the rest, up to the limit."""
    limit = int(MAX_RECORDING_SECONDS * info.samplerate)
    mono = np.empty(max(info.frames, 0), dtype=np.float32)
    beyond: list[np.ndarray] = []
    decoded = 0
    try:
        with sf.SoundFile(handle) as audio:
            for block in audio.blocks(BLOCK_FRAMES, dtype="float32", always_2d=True):
                samples = to_mono(block)
                if not np.all(np.isfinite(samples)):
                    raise ServantError(
                        f"{path}: holds samples that are not numbers (NaN or infinity); "
                        "the file is damaged, record it again"
                    )
                if decoded + len(samples) > limit:
                    raise _too_long(path)
                fits = max(0, min(len(samples), len(mono) - decoded))
                mono[decoded : decoded + fits] = samples[:fits]
                if fits < len(samples):
                    beyond.append(samples[fits:])
                decoded += len(samples)
    except (sf.LibsndfileError, RuntimeError, ValueError, TypeError, OSError) as exc:
        raise _not_readable(path, first_line(exc)) from None
    if decoded == 0:
        raise ServantError(f"{path}: the audio file is empty; record it again")
    return np.concatenate([mono, *beyond]) if beyond else mono[:decoded]


def first_line(exc: BaseException) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__


def window_length(rate: int, seconds: float) -> int:
    return int(round(rate * seconds))


def cut_windows(
    signal: np.ndarray, rate: int, seconds: float = DEFAULT_WINDOW_SECONDS
) -> np.ndarray:
    """Cut a mono signal into consecutive non-overlapping windows; the remainder is dropped.

    Returns a (n_windows, samples_per_window) view-free float32 array (possibly with 0 rows).
    """
    size = window_length(rate, seconds)
    count = len(signal) // size
    return np.ascontiguousarray(signal[: count * size], dtype=np.float32).reshape(count, size)


def duration_seconds(path: str | Path) -> float:
    """Length of an audio file from its header, without decoding it."""
    path = Path(path)
    with open_regular_file(path, "audio file") as handle:
        info = _checked_info(path, handle)
    return float(info.frames / info.samplerate)


def write_wav(path: str | Path, signal: np.ndarray, rate: int) -> Path:
    """Write mono float audio as a 16-bit WAV, atomically (recordings are never half-written)."""
    import io

    from servant_core.storage import atomic_write_bytes

    buffer = io.BytesIO()
    sf.write(buffer, np.clip(signal, -1.0, 1.0), rate, format="WAV", subtype="PCM_16")
    return atomic_write_bytes(path, buffer.getvalue())
