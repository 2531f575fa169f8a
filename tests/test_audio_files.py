import numpy as np
import pytest
import soundfile as sf

from servant_core.audio import cut_windows, read_audio, resample, to_mono, write_wav
from servant_core.errors import ServantError
from tests.conftest import tone


def peak_hz(signal: np.ndarray, rate: int) -> float:
    spectrum = np.abs(np.fft.rfft(signal))
    return float(np.fft.rfftfreq(len(signal), 1 / rate)[np.argmax(spectrum)])


def test_stereo_48k_file_is_mixed_to_mono_and_resampled(tmp_path):
    left = tone(1000, 1.0, 48000)
    stereo = np.stack([left, np.zeros_like(left)], axis=1)
    path = tmp_path / "stereo.flac"
    sf.write(path, stereo, 48000)
    signal = read_audio(path, rate=44100)
    assert signal.ndim == 1 and signal.dtype == np.float32
    assert abs(len(signal) - 44100) <= 1
    assert abs(peak_hz(signal, 44100) - 1000) <= 1.0
    # mixing averages the channels: a 0.5 tone on one channel becomes 0.25
    assert 0.22 < np.max(np.abs(signal[1000:-1000])) < 0.28


def test_to_mono_and_resample_identity():
    x = np.arange(6, dtype=np.float32).reshape(3, 2)
    assert np.allclose(to_mono(x), [0.5, 2.5, 4.5])
    y = np.ones(100, np.float32)
    assert resample(y, 44100, 44100) is not None and len(resample(y, 44100, 44100)) == 100


def test_cut_windows_drops_the_remainder():
    windows = cut_windows(np.arange(23, dtype=np.float32), rate=2, seconds=5)
    assert windows.shape == (2, 10)
    assert windows[1, 0] == 10


@pytest.mark.parametrize(
    "content, expected",
    [
        (b"", "not a readable audio file"),
        (b"this is not audio at all" * 10, "not a readable audio file"),
    ],
)
def test_bad_audio_files_give_one_clear_line(tmp_path, content, expected):
    path = tmp_path / "bad.wav"
    path.write_bytes(content)
    with pytest.raises(ServantError) as info:
        read_audio(path)
    message = str(info.value)
    assert str(path) in message and expected in message and "\n" not in message
    assert " object at 0x" not in message  # what libsndfile says, not the file object's repr


def test_truncated_wav_is_reported_or_read_partially(tmp_path):
    path = tmp_path / "whole.wav"
    write_wav(path, tone(440, 1.0, 8000), 8000)
    data = path.read_bytes()
    cut = tmp_path / "cut.wav"
    cut.write_bytes(data[:30])  # header only, cut inside it
    with pytest.raises(ServantError):
        read_audio(cut)


def test_empty_but_valid_wav_is_reported(tmp_path):
    path = tmp_path / "empty.wav"
    sf.write(path, np.zeros(0, np.float32), 8000)
    with pytest.raises(ServantError, match="empty"):
        read_audio(path)


def test_write_wav_is_atomic_and_round_trips(tmp_path):
    path = tmp_path / "rec" / "x.wav"
    write_wav(path, tone(440, 0.5, 8000), 8000)
    assert [p.name for p in path.parent.iterdir()] == ["x.wav"]
    assert abs(peak_hz(read_audio(path, 8000), 8000) - 440) < 3


# Issue 13 item 4 and 9: the header is checked before decoding; odd names and NaN samples.


def wav_with_rate_field(tmp_path, rate_field: int):
    """A 2 s, 8 kHz WAV whose header then claims `rate_field` Hz."""
    path = tmp_path / "claims.wav"
    write_wav(path, tone(440, 2.0, 8000), 8000)
    data = bytearray(path.read_bytes())
    assert data[24:28] == (8000).to_bytes(4, "little")  # the RIFF fmt chunk's sample rate
    data[24:28] = rate_field.to_bytes(4, "little")
    path.write_bytes(bytes(data))
    return path


@pytest.mark.parametrize("rate_field", [1, 7999, 192001, 2**31 - 1])
def test_a_header_claiming_an_odd_rate_is_refused_before_decoding(tmp_path, rate_field):
    path = wav_with_rate_field(tmp_path, rate_field)
    with pytest.raises(ServantError, match="sample rate") as info:
        read_audio(path)  # before: 1 Hz asked for 5.6 GB (resampling 16,000 samples to 44.1 kHz)
    assert "\n" not in str(info.value)


def test_too_many_channels_or_too_long_is_refused(tmp_path):
    path = tmp_path / "many.wav"
    sf.write(path, np.zeros((10, 17), np.float32), 8000)
    with pytest.raises(ServantError, match="channels"):
        read_audio(path)
    from servant_core import audio

    long = tmp_path / "long.flac"
    sf.write(long, np.zeros(8000 * 3, np.float32), 8000)
    original = audio.MAX_RECORDING_SECONDS
    audio.MAX_RECORDING_SECONDS = 2.0  # instead of writing a 10-minute file
    try:
        with pytest.raises(ServantError, match="longer than"):
            read_audio(long)
    finally:
        audio.MAX_RECORDING_SECONDS = original


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_infinite_samples_are_marked_and_a_file_of_nothing_else_refused(tmp_path, bad):
    """A sample that is no number is NaN in what is read (its window is skipped downstream);
    the rest is kept. A file with no sample that is a number is refused."""
    signal = tone(440, 1.0, 8000)
    signal[100] = bad
    path = tmp_path / "nan.wav"
    sf.write(path, signal, 8000, subtype="FLOAT")
    heard = read_audio(path, 8000)
    assert np.isnan(heard[100]) and np.all(np.isfinite(np.delete(heard, 100)))
    sf.write(path, np.full(800, bad, np.float32), 8000, subtype="FLOAT")
    with pytest.raises(ServantError, match="no sample that is a number"):
        read_audio(path, 8000)


def test_a_missing_file_says_no_such_file(tmp_path):
    with pytest.raises(ServantError, match="no such file") as info:
        read_audio(tmp_path / "absent.wav")
    assert "System error" not in str(info.value)


@pytest.mark.timeout(20)
def test_a_fifo_is_refused_without_waiting_for_a_writer(tmp_path):
    import os

    fifo = tmp_path / "pipe.wav"
    os.mkfifo(fifo)
    with pytest.raises(ServantError, match="not a regular file"):
        read_audio(fifo)  # before: open() blocked until someone wrote into the pipe


def test_a_file_name_that_is_not_utf8_is_read(tmp_path):
    import os

    name = os.fsdecode(b"caf\xe9.wav")
    path = tmp_path / name
    write_wav(path, tone(440, 0.5, 8000), 8000)
    assert len(read_audio(path, 8000)) == 4000


def test_silence_is_below_minus_90_dbfs_and_a_window_that_is_not_numbers_is_not_silent():
    from servant_core.audio import is_silent, level_dbfs

    assert level_dbfs(np.ones(100, np.float32)) == pytest.approx(0.0)
    assert is_silent(np.zeros(100, np.float32)) and is_silent(np.full(100, 1e-5, np.float32))
    assert not is_silent(np.full(100, 1e-4, np.float32))  # -80 dBFS: a quiet room is a place
    # NaN or infinity: unusable (said as such elsewhere), not "the microphone is muted"
    assert not is_silent(np.array([np.nan, 0.0, 0.0], np.float32))
    assert not is_silent(np.array([np.inf, 0.0, 0.0], np.float32))
