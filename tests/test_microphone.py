"""The microphone through a real PortAudio input: a PulseAudio null sink we play into.

`make test` starts the virtual microphone (../shared/scripts/virtual-mic.sh) and exports its
environment; run alone, these tests start it themselves. They skip, saying why, only when
PulseAudio cannot be started on this machine.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from servant_core.audio import read_audio, write_wav
from servant_core.capture.microphone import Microphone, find_input_device, list_input_devices
from servant_core.engine import Engine
from servant_core.errors import ServantError
from servant_core.events import DeviceStatus, SpectrumFrame
from tests.conftest import REPO, shared_data_dir, tone

RATE = 44100  # the null sink's rate (virtual-mic.sh)


def _virtual_mic_script() -> Path | None:
    candidates = [REPO.parent / "shared" / "scripts" / "virtual-mic.sh"]
    data = shared_data_dir()
    if data is not None:
        candidates.append(data.parent / "scripts" / "virtual-mic.sh")
    return next((c for c in candidates if c.is_file()), None)


@pytest.fixture(scope="module")
def virtual_mic() -> None:
    """Make sure the PulseAudio null sink runs and this process talks to it."""
    if not os.environ.get("PULSE_SERVER"):
        script = _virtual_mic_script()
        if script is None:
            pytest.skip("no ../shared/scripts/virtual-mic.sh to start a virtual microphone")
        if shutil.which("pulseaudio") is None:
            pytest.skip("PulseAudio is not installed (scripts/install-system-packages installs it)")
        started = subprocess.run(["bash", str(script), "start"], capture_output=True, text=True)
        if started.returncode != 0 or "PULSE_SERVER=" not in started.stdout:
            pytest.skip(
                f"PulseAudio could not be started: {started.stderr.strip() or started.stdout}"
            )
        for pair in started.stdout.replace("export ", "").split():
            name, _, value = pair.partition("=")
            os.environ[name] = value
    probe = subprocess.run(["pactl", "info"], capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"PulseAudio is not answering: {probe.stderr.strip()}")


def play(path: Path) -> subprocess.Popen:
    """Play a file into the null sink (what the virtual microphone hears), in the background."""
    return subprocess.Popen(["paplay", "--device=vsink", str(path)], stderr=subprocess.PIPE)


def record_while_playing(engine: Engine, clip: np.ndarray, tmp_path: Path) -> np.ndarray:
    """Play `clip` (longer than 5 s) and take the engine's 5 s window from within it."""
    path = write_wav(tmp_path / "played.wav", clip, RATE)
    recorded: list[np.ndarray] = []
    player = play(path)
    time.sleep(0.8)  # the clip has started reaching the sink by now (latency ~ tens of ms)
    recorder = threading.Thread(target=lambda: recorded.append(engine.record_window(5.0)))
    recorder.start()
    recorder.join(timeout=20)
    assert player.wait(timeout=20) == 0, player.stderr.read() if player.stderr else ""
    assert recorded, "record_window returned nothing"
    return recorded[0]


def peak_hz(freqs: np.ndarray, db: np.ndarray) -> float:
    """The spectral peak, refined by a parabola through the top bin and its neighbours."""
    i = int(np.argmax(db[1:-1])) + 1
    a, b, c = db[i - 1], db[i], db[i + 1]
    offset = 0.5 * (a - c) / (a - 2 * b + c)
    return float(freqs[i] + offset * (freqs[1] - freqs[0]))


def test_lists_the_virtual_input_and_finds_it_by_name_and_index(virtual_mic):
    devices = list_input_devices()
    assert devices and any(d.is_default for d in devices)
    default = find_input_device(None)
    assert default.is_default
    assert find_input_device(default.index) == default
    assert (
        find_input_device(default.name[:3].upper())
        .name.lower()
        .startswith(default.name[:3].lower())
    )
    with pytest.raises(ServantError, match="no such input device"):
        find_input_device("no such microphone anywhere")


def test_a_reader_held_up_for_a_second_gets_all_of_it_at_once_and_loses_nothing(virtual_mic):
    """A sense thread held up (a busy machine, a long garbage collection) must catch up in one
    read, not one 20 ms block a turn: at one block a turn it never caught up, the queue filled,
    blocks were dropped and teach mode's 5 s recording timed out."""
    mic = Microphone()
    mic.open()
    try:
        assert mic.read(5.0) is not None  # the stream runs
        time.sleep(1.0)  # the reader is held up; PortAudio goes on queueing 20 ms blocks
        block = mic.read(1.0)
        assert block is not None
        assert len(block) >= 0.8 * mic.rate, f"{len(block) / mic.rate:.2f} s in one read"
        assert mic.overflows == 0
    finally:
        mic.close()


def test_engine_window_and_spectrum_frames_contain_a_played_tone(virtual_mic, tmp_path):
    frames: list[SpectrumFrame] = []
    mic = Microphone(rate=RATE)
    engine = Engine(audio=mic)
    engine.subscribe(lambda e: frames.append(e) if isinstance(e, SpectrumFrame) else None)
    with engine:
        assert engine.status["microphone"].ok, engine.status["microphone"].message
        assert engine.audio_rate == RATE
        started = time.monotonic()
        window = record_while_playing(engine, tone(997.0, 7.0, RATE, 0.5), tmp_path)
        elapsed = time.monotonic() - started

    assert window.shape == (5 * RATE,) and window.dtype == np.float32
    spectrum = np.abs(np.fft.rfft(window))
    freqs = np.fft.rfftfreq(len(window), 1 / RATE)
    assert abs(freqs[np.argmax(spectrum)] - 997.0) <= 2.0
    assert 0.3 < np.sqrt(np.mean(window**2)) < 0.4  # a 0.5 sine's RMS is 0.354: nothing lost

    loud = [f for f in frames if f.magnitude_db.max() > -20]
    assert len(loud) > 100, f"only {len(loud)} spectrum frames heard the tone"
    peaks = np.array([peak_hz(f.freqs, f.magnitude_db) for f in loud])
    assert np.median(np.abs(peaks - 997.0)) <= 2.0
    assert np.mean(np.abs(peaks - 997.0) <= 2.0) > 0.9
    rate = len(frames) / elapsed
    assert 20 <= rate <= 40, f"{rate:.1f} spectrum frames per second"
    assert all(len(f.freqs) == 1025 for f in frames[:5])  # 2048-sample frames, not the ring


@pytest.mark.slow
def test_engine_window_correlates_with_a_played_recording(virtual_mic, tmp_path, shared_data):
    recording = read_audio(shared_data / "audio/dev/street/moodist-traffic.mp3", RATE)
    clip = recording[10 * RATE : 17 * RATE]
    clip = 0.5 * clip / np.max(np.abs(clip))
    with Engine(audio=Microphone(rate=RATE)) as engine:
        window = record_while_playing(engine, clip, tmp_path)

    # Where in the played clip does the window sit? Cross-correlate, then compare at that lag.
    n = len(clip) + len(window)
    xcorr = np.fft.irfft(np.fft.rfft(clip, n) * np.conj(np.fft.rfft(window, n)), n)
    lag = int(np.argmax(xcorr[: len(clip)]))
    assert 0 < lag and lag + len(window) <= len(clip), lag
    played = clip[lag : lag + len(window)]
    r = np.corrcoef(played, window)[0, 1]
    assert r > 0.98, f"correlation {r:.3f}"


def test_a_missing_device_is_reported_once_and_the_engine_runs_on(virtual_mic):
    statuses: list[DeviceStatus] = []
    engine = Engine(audio=Microphone("no such microphone anywhere"), reopen_seconds=0.1)
    engine.subscribe(lambda e: statuses.append(e) if isinstance(e, DeviceStatus) else None)
    with engine:
        time.sleep(0.6)  # several reopen attempts
        assert engine.running
    problems = [s for s in statuses if s.device == "microphone" and not s.ok]
    assert len(problems) == 1
    assert "no such input device" in problems[0].message


def test_without_portaudio_the_engine_says_so_in_one_line_and_runs():
    # PortAudio cannot be uninstalled for a test, so the child process makes `import sounddevice`
    # raise the OSError it raises when libportaudio is missing.
    code = """
import sys
class NoPortAudio:
    def find_spec(self, name, path=None, target=None):
        if name == "sounddevice":
            raise OSError("PortAudio library not found")
sys.meta_path.insert(0, NoPortAudio())
import time, servant_core, servant_core.engine
from servant_core.engine import LiveSettings, build_live_engine
engine = build_live_engine(LiveSettings(camera=None))
engine.subscribe(lambda e: print(type(e).__name__, getattr(e, "ok", ""), getattr(e, "message", "")))
engine.start(); time.sleep(0.2); print("running", engine.running); engine.stop()
"""
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    problem = [line for line in lines if line.startswith("DeviceStatus False microphone")]
    assert len(problem) == 1 and "PortAudio library is missing" in problem[0]
    assert "libportaudio2" in problem[0]
    assert "running True" in lines


HOT_PLUG = """
import os
real = os.environ["PULSE_SERVER"]
os.environ["PULSE_SERVER"] = "unix:/nonexistent/pulse/native"  # no sound server: no device
from servant_core.capture.microphone import Microphone
from servant_core.errors import ServantError
microphone = Microphone()
try:
    microphone.open()
    print("opened without a device")
except ServantError as error:
    print("first:", error)
os.environ["PULSE_SERVER"] = real  # the microphone is plugged in
microphone.open()
print("second: recording from", microphone.name)
microphone.close()
"""


def test_a_microphone_plugged_in_after_start_is_found_when_opened_again(virtual_mic):
    """PortAudio lists the devices there were when it started: a wearer who plugs the microphone
    in after starting Servant (or whose USB microphone comes back under another number) got
    "no input device found" at every reopen. Now an open that finds no device starts PortAudio
    again and looks once more. A process of its own, so PortAudio starts with no device."""
    done = subprocess.run(
        [sys.executable, "-c", HOT_PLUG], capture_output=True, text=True, timeout=120, cwd=REPO
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "first: microphone: no input device found" in done.stdout
    assert "second: recording from microphone" in done.stdout
