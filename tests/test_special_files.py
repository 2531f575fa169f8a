"""Special files where a file is read (issue 24 item 5): a FIFO, a link to /dev/zero, a
camera path that is a FIFO, a recording whose disk answers EIO. Each is one line, at once:
never a hang, never a read until memory is gone, never a dozen lines of tracebacks."""

from __future__ import annotations

import errno
import io
import os
from pathlib import Path

import pytest

import servant_core.audio as audio
from servant_core.audio import read_audio, write_wav
from servant_core.capture.camera import Camera
from servant_core.errors import ServantError
from tests.cli_harness import assert_clear, run_cli_subprocess
from tests.conftest import tone
from tests.test_cli_boundaries import audio_library

SPECIAL = ["fifo", "zero"]


def special(path: Path, kind: str) -> Path:
    if kind == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to("/dev/zero")
    return path


@pytest.mark.devices
@pytest.mark.parametrize("kind", SPECIAL)
def test_settings_as_a_special_file_are_one_line(tmp_path: Path, kind: str) -> None:
    settings = special(tmp_path / "settings.json", kind)
    outcome = run_cli_subprocess(
        "servo", "move", "--settings", str(settings), "--dry-run", "shoulder=10", timeout=30
    )
    assert_clear(outcome, seconds=30)
    assert outcome.code == 2 and "not a regular file" in outcome.err
    assert outcome.peak_mb < 500


@pytest.mark.devices
@pytest.mark.parametrize("kind", SPECIAL)
def test_teach_records_as_a_special_file_are_one_line(tmp_path: Path, kind: str) -> None:
    records = special(tmp_path / "records.json", kind)
    outcome = run_cli_subprocess(
        "teach", "--records", str(records), "--learner", str(tmp_path / "l.npz"), timeout=30
    )
    assert_clear(outcome, seconds=30)
    # a link is refused as the place to write the records, before it is read
    assert outcome.code == 2
    assert ("not a regular file" if kind == "fifo" else "symbolic link") in outcome.err


@pytest.mark.devices
@pytest.mark.parametrize("kind", SPECIAL)
def test_a_groups_file_as_a_special_file_is_one_line(tmp_path: Path, kind: str) -> None:
    """`eval audio --protocol source --groups FIFO` waited for a writer for ever (and a link to
    /dev/zero read until memory was gone): the groups file was read with `read_text`."""
    lib = audio_library(tmp_path / "lib")
    groups = special(tmp_path / "groups.txt", kind)
    outcome = run_cli_subprocess(
        "eval", "audio", str(lib), "--protocol", "source", "--groups", str(groups), timeout=30
    )
    assert_clear(outcome, seconds=30)
    assert outcome.code == 2 and "not a regular file" in outcome.err


@pytest.mark.devices
@pytest.mark.parametrize("kind", SPECIAL)
def test_a_model_as_a_special_file_is_one_line(tmp_path: Path, kind: str) -> None:
    model = special(tmp_path / "model.npz", kind)
    outcome = run_cli_subprocess("predict", str(model), "--image", "x.png", timeout=30)
    assert_clear(outcome, seconds=30)
    assert outcome.code == 2 and "not a regular file" in outcome.err


@pytest.mark.devices
def test_a_camera_path_that_is_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    fifo = special(tmp_path / "camera.mp4", "fifo")
    with pytest.raises(ServantError, match="not a video file"):
        Camera(str(fifo)).open()
    outcome = run_cli_subprocess(
        "run", "--headless", "--no-mic", "--camera", str(fifo), "--duration", "0.5", timeout=60
    )
    assert outcome.seconds < 30, outcome
    assert "Traceback" not in outcome.err


def test_a_camera_index_beyond_any_is_one_line() -> None:
    with pytest.raises(ServantError, match="no such camera"):
        Camera("999999999999999999999").open()


class FailingDisk(io.RawIOBase):
    """A file whose reads fail with EIO after `good` bytes, as a failing disk's do."""

    def __init__(self, data: bytes, good: int) -> None:
        self.data, self.good, self.at = data, good, 0

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        self.at = {0: offset, 1: self.at + offset, 2: len(self.data) + offset}[whence]
        return self.at

    def tell(self) -> int:
        return self.at

    def readinto(self, buffer) -> int:
        if self.at + len(buffer) > self.good:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        chunk = self.data[self.at : self.at + len(buffer)]
        buffer[: len(chunk)] = chunk
        self.at += len(chunk)
        return len(chunk)


@pytest.mark.parametrize("good", [0, 100, 40_000])
@pytest.mark.filterwarnings("error::RuntimeWarning")  # the failed read's garbage averaged loudly
def test_a_recording_whose_disk_fails_is_one_line_and_quiet(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str], good: int
) -> None:
    path = write_wav(tmp_path / "r.wav", tone(440, 5.0, 8000), 8000)
    data = path.read_bytes()
    monkeypatch.setattr(audio, "open_regular_file", lambda *_: FailingDisk(data, good))
    with pytest.raises(ServantError) as refused:
        read_audio(path, 8000)
    assert "Input/output error" in str(refused.value) and "\n" not in str(refused.value)
    err = capfd.readouterr().err
    assert "Exception ignored" not in err and "Traceback" not in err


@pytest.mark.devices
@pytest.mark.parametrize("kind", ["loop", "dangling"])
def test_settings_or_records_behind_a_link_to_no_file_are_one_line(tmp_path: Path, kind: str):
    """A settings file that was a loop of links (or a link whose target is gone) was taken for
    "no settings yet": the arm moved with the default joints, silently. Teach records likewise."""
    for name in ("settings.json", "records.json"):
        link = tmp_path / name
        link.symlink_to(tmp_path / f"{name}.loop" if kind == "loop" else tmp_path / "gone")
        if kind == "loop":
            (tmp_path / f"{name}.loop").symlink_to(link)
    settings = run_cli_subprocess(
        "servo", "move", "--settings", str(tmp_path / "settings.json"), "--dry-run", "shoulder=10"
    )
    assert_clear(settings, seconds=30)
    assert settings.code == 2 and "a link that leads to no file" in settings.err
    from servant_core.actions.records import load_records

    with pytest.raises(ServantError, match="a link that leads to no file"):
        load_records(tmp_path / "records.json")
