"""Finite values that would overflow inside the features are refused where they are read, and
no feature row that is not finite numbers reaches a fit, a prediction or a fold-in (issue 24
item 4): a float32 file at its maximum, sensor values beyond 3.4e38, ambient values of 1e307,
an MP3 whose damaged frames decode to samples thousands of times full scale."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
import soundfile as sf

from servant_core import library
from servant_core.audio import MAX_AMPLITUDE, read_audio
from servant_core.capture.sample_files import read_sample_csv
from servant_core.capture.sensors import parse_line
from servant_core.engine import Engine
from servant_core.errors import ServantError
from servant_core.events import ErrorEvent, Notice, SensePrediction
from servant_core.features.rows import usable_rows
from servant_core.library import Recording, featurize_recordings
from servant_core.recognisers import make_recogniser
from tests.cli_harness import assert_clear, assert_refused, run_cli
from tests.test_cli_boundaries import SMALL_AUDIO, audio_library
from tests.test_motion_sense import training

FLOAT32_MAX = float(np.finfo(np.float32).max)
IMU_HEADER = "time,ax,ay,az,gx,gy,gz\n"


def float_wav(path: Path, value: float, seconds: float = 1.0) -> Path:
    samples = np.full(int(8000 * seconds), value, np.float32)
    samples[::2] *= -1
    sf.write(path, samples, 8000, subtype="FLOAT")
    return path


def test_usable_rows_are_numbers_within_the_limit() -> None:
    X = np.array([[1.0, 2.0], [np.nan, 0.0], [np.inf, 0.0], [1e300, 0.0], [-3.0, 1e9]])
    assert usable_rows(X).tolist() == [True, False, False, False, True]
    assert usable_rows(np.zeros((0, 4))).shape == (0,)


def test_a_float_file_at_the_float32_maximum_is_refused(tmp_path: Path) -> None:
    path = float_wav(tmp_path / "maxfloat.wav", FLOAT32_MAX)
    with pytest.raises(ServantError, match="no sample that is a number within ±1000 times full"):
        read_audio(path, 8000)
    loud = float_wav(tmp_path / "loud.wav", 2.0)  # beyond full scale, but a real mix can be
    assert np.abs(read_audio(loud, 8000)).max() == pytest.approx(2.0)


def test_train_and_predict_with_a_maxfloat_recording(tmp_path: Path) -> None:
    lib = audio_library(tmp_path / "lib")
    bad = float_wav(lib / "gym" / "maxfloat.wav", FLOAT32_MAX)
    model = tmp_path / "m.npz"
    assert_refused(run_cli("train", str(lib), "-o", str(model), *SMALL_AUDIO), "maxfloat.wav")
    skipped = run_cli("train", str(lib), "-o", str(model), *SMALL_AUDIO, "--skip-bad")
    assert skipped.code == 0 and "maxfloat.wav" in skipped.err
    assert_refused(run_cli("predict", str(model), "--audio", str(bad)), "full scale")


def test_feature_rows_that_are_not_numbers_are_left_out_with_one_line(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    windows = np.zeros((4, 80), np.float32)

    def featurize(w: np.ndarray) -> np.ndarray:
        X = np.ones((len(w), 3))
        X[1] = np.nan
        return X

    said: list[ServantError] = []
    recordings = [Recording("cafe", Path("a.wav"))]
    monkeypatch.setattr(
        library, "iter_recording_windows", lambda *a, **k: iter([(0, recordings[0], windows)])
    )
    kept = featurize_recordings(recordings, featurize, on_error=said.append)
    with pytest.raises(ServantError, match="not finite"):
        featurize_recordings(recordings, featurize)
    assert len(said) == 1 and "1 of 4 windows" in str(said[0])
    assert kept.features.shape == (3, 3) and kept.position.tolist() == [0, 2, 3]


@pytest.mark.parametrize(
    "kind,row",
    [
        ("imu", "{t},3.5e38,0,9.8,0,0,0"),  # beyond float32: once cast to infinity
        ("imu", "{t},1e39,0,9.8,0,0,0"),
        ("ambient", "{t},1e307,20,1013"),  # finite, but its square is not
        ("ambient", "{t},300,20,1e30"),
    ],
)
def test_sensor_rows_beyond_the_sensor_are_skipped(tmp_path: Path, kind: str, row: str) -> None:
    header = IMU_HEADER if kind == "imu" else "time,lux,celsius,hpa\n"
    good = "{t},0,0,9.8,0,0,0" if kind == "imu" else "{t},300,20,1013"
    rows = [(row if i % 5 == 2 else good).format(t=i * 0.01) for i in range(40)]
    path = tmp_path / f"log.{kind}.csv"
    path.write_text(header + "\n".join(rows) + "\n")
    log = read_sample_csv(path, kind)
    assert log.skipped == 8 and np.isfinite(log.values).all()
    with pytest.raises(ValueError, match="beyond"):
        tag = "I" if kind == "imu" else "A"
        parse_line(f"{tag},{row.format(t=5)}\n".encode())


def test_a_log_that_is_all_beyond_the_sensor_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "log.ambient.csv"
    rows = [f"{i * 0.1},1e307,20,1013" for i in range(40)]
    path.write_text("time,lux,celsius,hpa\n" + "\n".join(rows) + "\n")
    with pytest.raises(ServantError, match="within what a ambient sensor reads|units"):
        read_sample_csv(path, "ambient")


def test_live_unusable_windows_are_one_notice_then_quiet_until_a_good_one() -> None:
    model = make_recogniser("motion", "kmeans")
    windows, scenes = training("motion", per_scene=8)
    model.fit(model.featurize(windows), scenes)
    engine = Engine(sample_recognisers={"motion": model})
    events: list = []
    engine.subscribe(events.append)
    huge = np.full_like(windows[0], 1e30)  # finite float32, but its features overflow

    def window(rows: np.ndarray) -> None:
        engine._judge.guarded(
            "motion prediction", engine._judge.on_samples, "motion", rows, model.rate
        )

    for _ in range(5):
        window(huge)
    notices = [e for e in events if isinstance(e, Notice)]
    assert len(notices) == 1 and "skipped a window" in notices[0].message
    assert not [e for e in events if isinstance(e, ErrorEvent | SensePrediction)]
    window(windows[0])
    assert [e for e in events if isinstance(e, SensePrediction)]
    window(huge)
    assert len([e for e in events if isinstance(e, Notice)]) == 2


def damaged_mp3() -> bytes:
    """An MP3 with a few bytes changed so that its damaged frames decode far beyond full
    scale: found among seeded corruptions of a tone (libmpg123 decodes such frames into
    samples of thousands, and on some runs into values that overflow the features)."""
    rng = np.random.default_rng(1)
    rate = 8000
    t = np.arange(3 * rate) / rate
    tone = (0.5 * np.sin(2 * np.pi * 440 * t) + 0.01 * rng.standard_normal(len(t))).astype(
        np.float32
    )
    buffer = io.BytesIO()
    sf.write(buffer, tone, rate, format="MP3")
    good = buffer.getvalue()
    for _ in range(5000):
        data = bytearray(good)
        for _ in range(rng.integers(1, 9)):
            data[rng.integers(0, len(data))] = rng.integers(0, 256)
        try:
            samples, _ = sf.read(io.BytesIO(bytes(data)), dtype="float32")
        except (sf.LibsndfileError, RuntimeError):
            continue
        if samples.size and not np.all(np.abs(samples) <= MAX_AMPLITUDE):
            return bytes(data)
    pytest.skip("no corruption of the MP3 decodes beyond full scale with this libmpg123")


def test_a_damaged_mp3_decoded_30_times_is_refused_each_time(tmp_path: Path) -> None:
    lib = audio_library(tmp_path / "lib")
    model = tmp_path / "m.npz"
    assert run_cli("train", str(lib), "-o", str(model), *SMALL_AUDIO).code == 0
    path = tmp_path / "damaged.mp3"
    path.write_bytes(damaged_mp3())
    for _ in range(30):
        outcome = run_cli("predict", str(model), "--audio", str(path))
        assert_clear(outcome)
        assert "nan" not in outcome.out.lower()
