"""Audio files: read any rate or channel count, mix to mono, resample, cut into windows."""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import Any, BinaryIO, TypeVar

import numpy as np
import soundfile as sf

from servant_core.choices import DEFAULT_RATE as DEFAULT_RATE  # the audio's names, kept light
from servant_core.choices import DEFAULT_WINDOW_SECONDS as DEFAULT_WINDOW_SECONDS
from servant_core.choices import MAX_RATE as MAX_RATE
from servant_core.choices import MAX_WINDOW_SECONDS as MAX_WINDOW_SECONDS
from servant_core.choices import MIN_RATE as MIN_RATE
from servant_core.choices import MIN_WINDOW_SECONDS as MIN_WINDOW_SECONDS
from servant_core.errors import ServantError
from servant_core.senses import AUDIO_SUFFIXES as AUDIO_SUFFIXES
from servant_core.storage import atomic_write_bytes, open_regular_file, os_reason

# What a recording or a model may claim (rates, window lengths: in `choices`). Ten minutes keeps
# the decoded mono copy and its resampled copy of a 192 kHz file well under a gigabyte; longer
# recordings can be cut up.
MAX_CHANNELS = 16
MAX_RECORDING_SECONDS = 600.0
BLOCK_FRAMES = 1 << 16
T = TypeVar("T")
# Full scale is ±1. A float file may go beyond it (a mix not normalised), but not a thousand
# times: such samples (a float32 file at its maximum, a damaged MP3 frame) overflow the
# features' squares and sums into infinity and NaN.
MAX_AMPLITUDE = 1000.0
# Below this level (RMS, dB relative to full scale) a window is silence, not a place: a muted or
# unplugged microphone, a paused stream. 16-bit quantisation noise alone is about -101 dBFS; the
# quietest 5 s of the 84 dev recordings (a train at night) is -78 dBFS.
SILENT_DBFS = -90.0


def to_mono(samples: np.ndarray) -> np.ndarray:
    """Average the channels of a (frames, channels) array; a 1-D array is already mono."""
    samples = np.asarray(samples, dtype=np.float32)
    if samples.ndim == 1:
        return samples
    # a damaged block (infinities: a broken MP3 frame, a read that failed part way) averages to
    # NaN quietly; the decoder marks such samples damaged right after
    with np.errstate(invalid="ignore", over="ignore"):
        return samples.mean(axis=1, dtype=np.float32)


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

    def decode(handle: Any) -> tuple[Any, np.ndarray]:
        info = _checked_info(path, handle)
        handle.seek(0)
        return info, _decode_mono(path, handle, info)

    info, mono = _through_callbacks(path, decode)
    return resample(mono, info.samplerate, rate)


class _ErrorsKept:
    """A file as libsndfile reads it, through callbacks an exception cannot pass (C is between):
    Python would print each as `Exception ignored from cffi callback` and a traceback, a dozen
    lines over the terminal, before libsndfile's own error. An I/O error (EIO from a failing
    disk) is kept here instead, the read answered as the end of the file, and the error raised
    by `raise_kept` once libsndfile has returned."""

    def __init__(self, handle: BinaryIO) -> None:
        self.handle = handle
        self.error: OSError | None = None

    def _kept(self, call: Callable[[], Any], fallback: Any) -> Any:
        try:
            return call()
        except OSError as exc:
            self.error = self.error or exc
            return fallback

    def readinto(self, buffer: Any) -> int:
        return int(self._kept(lambda: self.handle.readinto(buffer), 0))  # type: ignore[attr-defined]

    def read(self, size: int = -1) -> bytes:
        return bytes(self._kept(lambda: self.handle.read(size), b""))

    def seek(self, offset: int, whence: int = 0) -> int:
        return int(self._kept(lambda: self.handle.seek(offset, whence), 0))

    def tell(self) -> int:
        return int(self._kept(self.handle.tell, 0))

    def raise_kept(self, path: Path) -> None:
        if self.error is not None:
            raise ServantError(
                f"{path}: cannot read the audio file ({os_reason(self.error)}); check the disk, "
                "or copy the file again"
            ) from None


def _through_callbacks(path: Path, use: Callable[[Any], T]) -> T:
    """`use(file)` on the audio file opened for libsndfile; an I/O error while it reads is one
    ServantError, said before whatever libsndfile made of the short read."""
    with open_regular_file(path, "audio file") as handle:
        source = _ErrorsKept(handle)
        try:
            result = use(source)
        except ServantError:
            source.raise_kept(path)
            raise
        source.raise_kept(path)
        return result


def _not_readable(path: Path, reason: str) -> ServantError:
    return ServantError(f"{path}: not a readable audio file ({reason}); use WAV, FLAC, OGG or MP3")


def _reason(exc: Exception) -> str:
    """What went wrong, in one line: libsndfile's own words, without the file object's repr
    (`Error opening <…_ErrorsKept object at 0x7f…>: Format not recognised.`) its str adds."""
    if isinstance(exc, sf.LibsndfileError):
        return exc.error_string.rstrip(".")
    return first_line(exc)


def _checked_info(path: Path, handle: Any) -> Any:
    try:
        info = sf.info(handle)
    except (sf.LibsndfileError, RuntimeError, ValueError, TypeError) as exc:
        raise _not_readable(path, _reason(exc)) from None
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


def _decode_mono(path: Path, handle: Any, info: Any) -> np.ndarray:
    """Decode block by block into one mono array sized from the header (a list of blocks and
    their concatenation would hold the recording twice); a header that under-states the
    length still gets the rest, up to the limit."""
    limit = int(MAX_RECORDING_SECONDS * info.samplerate)
    mono = np.empty(max(info.frames, 0), dtype=np.float32)
    beyond: list[np.ndarray] = []
    decoded = damaged = 0
    try:
        with sf.SoundFile(handle) as audio:
            for block in audio.blocks(BLOCK_FRAMES, dtype="float32", always_2d=True):
                samples = to_mono(block)
                # A damaged stretch (NaN, infinity, or beyond ±MAX_AMPLITUDE: an MP3's broken
                # frames, which libmpg123 decodes differently from one run to the next) becomes
                # NaN: the windows it falls in are skipped, each said in one line, the rest of
                # the recording is kept.
                bad = ~(np.abs(samples) <= MAX_AMPLITUDE)
                if np.any(bad):
                    samples = np.where(bad, np.float32(np.nan), samples)
                    damaged += int(np.count_nonzero(bad))
                if decoded + len(samples) > limit:
                    raise _too_long(path)
                fits = max(0, min(len(samples), len(mono) - decoded))
                mono[decoded : decoded + fits] = samples[:fits]
                if fits < len(samples):
                    beyond.append(samples[fits:])
                decoded += len(samples)
    except (sf.LibsndfileError, RuntimeError, ValueError, TypeError, OSError) as exc:
        raise _not_readable(path, _reason(exc)) from None
    if decoded == 0:
        raise ServantError(f"{path}: the audio file is empty; record it again")
    if damaged == decoded:
        raise ServantError(
            f"{path}: holds no sample that is a number within ±{MAX_AMPLITUDE:g} times full "
            "scale; the file is damaged, record it again"
        )
    return np.concatenate([mono, *beyond]) if beyond else mono[:decoded]


def level_dbfs(window: np.ndarray) -> float:
    """The RMS level of `window` in dB relative to full scale (±1); -inf for exact zeros, NaN
    when a sample is not a number (such a window is unusable, not silent)."""
    samples = np.asarray(window, dtype=np.float64).ravel()
    power = float(samples @ samples) / samples.size if samples.size else 0.0
    return 10.0 * math.log10(power) if power != 0 else float("-inf")


def is_silent(window: np.ndarray) -> bool:
    """Whether `window` is below `SILENT_DBFS`: it says nothing about where the wearer is."""
    return level_dbfs(window) < SILENT_DBFS  # False for NaN


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
    info = _through_callbacks(path, lambda handle: _checked_info(path, handle))
    return float(info.frames / info.samplerate)


def write_wav(path: str | Path, signal: np.ndarray, rate: int) -> Path:
    """Write mono float audio as a 16-bit WAV, atomically (recordings are never half-written)."""
    import io

    buffer = io.BytesIO()
    sf.write(buffer, np.clip(signal, -1.0, 1.0), rate, format="WAV", subtype="PCM_16")
    return atomic_write_bytes(path, buffer.getvalue())
