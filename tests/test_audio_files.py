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
