"""Audio files: read any rate or channel count, mix to mono, resample, cut into windows."""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import soundfile as sf
from scipy.signal import resample_poly

from servant_core.errors import ServantError

AUDIO_SUFFIXES = (".wav", ".flac", ".ogg", ".mp3")
DEFAULT_RATE = 44100
DEFAULT_WINDOW_SECONDS = 5.0


def to_mono(samples: np.ndarray) -> np.ndarray:
    """Average the channels of a (frames, channels) array; a 1-D array is already mono."""
    samples = np.asarray(samples, dtype=np.float32)
    return samples if samples.ndim == 1 else samples.mean(axis=1, dtype=np.float32)


def resample(signal: np.ndarray, rate_in: int, rate_out: int) -> np.ndarray:
    """Polyphase resampling (anti-aliased) from `rate_in` to `rate_out`."""
    if rate_in == rate_out:
        return np.asarray(signal, dtype=np.float32)
    ratio = Fraction(rate_out, rate_in)
    out = resample_poly(signal, ratio.numerator, ratio.denominator)
    return out.astype(np.float32, copy=False)


def read_audio(path: str | Path, rate: int = DEFAULT_RATE) -> np.ndarray:
    """Read an audio file as mono float32 at `rate`; a bad file raises one clear ServantError."""
    path = Path(path)
    try:
        samples, file_rate = sf.read(str(path), dtype="float32", always_2d=True)
    except (sf.LibsndfileError, RuntimeError, OSError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ServantError(
            f"{path}: not a readable audio file ({reason}); use WAV, FLAC, OGG or MP3"
        ) from exc
    if samples.shape[0] == 0:
        raise ServantError(f"{path}: the audio file is empty; record it again")
    return resample(to_mono(samples), int(file_rate), rate)


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
    try:
        info = sf.info(str(path))
    except (sf.LibsndfileError, RuntimeError, OSError) as exc:
        raise ServantError(f"{path}: not a readable audio file ({exc})") from exc
    return info.frames / info.samplerate if info.samplerate else math.nan


def write_wav(path: str | Path, signal: np.ndarray, rate: int) -> Path:
    """Write mono float audio as a 16-bit WAV, atomically (recordings are never half-written)."""
    import io

    from servant_core.storage import atomic_write_bytes

    buffer = io.BytesIO()
    sf.write(buffer, np.clip(signal, -1.0, 1.0), rate, format="WAV", subtype="PCM_16")
    return atomic_write_bytes(path, buffer.getvalue())
