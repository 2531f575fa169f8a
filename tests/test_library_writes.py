"""The scene library writes teach mode's recordings, pictures and sample logs
(`SceneLibrary.add_*`): each file whole or not at all, a failure one ServantError line that keeps
what was there, and the scene's name by the place-name rule."""

from __future__ import annotations

import errno
import os
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest

from servant_core.audio import read_audio
from servant_core.capture.sample_files import read_samples
from servant_core.capture.sensors import IMU_CHANNELS
from servant_core.errors import ServantError
from servant_core.library import SceneLibrary, read_picture, sample_log_text, teach_stem

RATE = 16_000
SOUND = np.linspace(-0.5, 0.5, RATE, dtype=np.float32)
FRAME = np.arange(8 * 6 * 3, dtype=np.uint8).reshape(8, 6, 3)
MOTION = np.tile(np.array([0.0, 0.0, 9.8, 0.1, 0.2, 0.3], dtype=np.float32), (100, 1))


def add(library: SceneLibrary, kind: str, scene: str = "cafe", stem: str = "teach-1") -> Path:
    if kind == "recording":
        return library.add_recording(scene, SOUND, RATE, stem)
    if kind == "picture":
        return library.add_picture(scene, FRAME, stem)
    return library.add_samples(scene, "motion", MOTION, 50, IMU_CHANNELS, stem)


def files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


def test_each_kind_is_written_into_the_scene_folder_and_reads_back(tmp_path) -> None:
    library = SceneLibrary.at(tmp_path / "library")  # no folder yet: the first write makes it
    sound, picture, motion = (add(library, kind) for kind in ("recording", "picture", "samples"))
    assert [p.relative_to(library.root) for p in (sound, picture, motion)] == [
        Path("cafe/teach-1.wav"),
        Path("cafe/teach-1.png"),
        Path("cafe/teach-1.imu.csv"),
    ]
    assert np.allclose(read_audio(sound, RATE), SOUND, atol=1e-4)
    assert np.array_equal(read_picture(picture), FRAME)
    assert np.allclose(read_samples(motion, "imu", 50), MOTION, atol=1e-3)
    scanned = SceneLibrary.scan(library.root)
    assert scanned.scenes == ["cafe"]
    assert [r.path for r in scanned.recordings] == [sound]
    assert [p.path for p in scanned.pictures] == [picture]
    assert [f.path for f in scanned.samples["motion"]] == [motion]


def test_files_are_named_by_the_time_unless_given_a_stem() -> None:
    assert teach_stem(datetime(2025, 3, 14, 9, 30, 15, 123456)) == "teach-20250314-093015-123456"


@pytest.mark.parametrize("kind", ["recording", "picture", "samples"])
@pytest.mark.parametrize(
    "stage", ["servant_core.storage.os.replace", "servant_core.storage.os.fsync"]
)
def test_a_failed_write_leaves_no_part_of_a_file_and_keeps_what_was_there(
    tmp_path, monkeypatch, kind, stage
) -> None:
    library = SceneLibrary.at(tmp_path / "library")
    add(library, kind)
    before = files(library.root)

    def disk_full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(stage, disk_full)
    with pytest.raises(ServantError) as failed:
        add(library, kind)  # the same name again: the file there is to be replaced
    assert os.strerror(errno.ENOSPC) in str(failed.value) and "\n" not in str(failed.value)
    assert files(library.root) == before, "the file there is kept whole, no temporary is left"


def test_a_library_that_cannot_be_made_is_one_servant_error(tmp_path) -> None:
    (tmp_path / "blocked").write_text("mine")
    library = SceneLibrary.at(tmp_path / "blocked" / "library")
    with pytest.raises(ServantError, match="recording cannot be written"):
        add(library, "recording")
    assert (tmp_path / "blocked").read_text() == "mine"


@pytest.mark.parametrize("scene", ["x" * 300, "a/b", "..", ".hidden", "a\nb", "<unknown>"])
def test_a_scene_name_the_rule_refuses_writes_nothing(tmp_path, scene) -> None:
    library = SceneLibrary.at(tmp_path / "library")
    with pytest.raises(ServantError, match="instead"):
        add(library, "recording", scene=scene)
    assert not (tmp_path / "library").exists() or files(tmp_path / "library") == {}


@pytest.mark.parametrize("stem", ["../teach-1", ".teach-1"])
def test_a_stem_that_is_not_a_plain_visible_name_is_a_mistake(tmp_path, stem) -> None:
    with pytest.raises(ValueError, match="plain"):
        add(SceneLibrary.at(tmp_path / "library"), "picture", stem=stem)
    assert not (tmp_path / "library").exists()


def test_a_scene_already_in_the_library_is_written_in_its_spelling(tmp_path) -> None:
    library = SceneLibrary.at(tmp_path / "library")
    (library.root / "cafe").mkdir(parents=True)
    assert add(library, "picture", scene="Cafe").parent == library.root / "cafe"


def test_a_sample_log_is_a_header_and_a_row_a_reading() -> None:
    text = sample_log_text(np.array([[1.0, 2.0], [3.0, 4.5]]), 2, ("lux", "hpa"))
    assert text == "time,lux,hpa\n0.0000,1.0000,2.0000\n0.5000,3.0000,4.5000\n"
    with pytest.raises(ValueError, match="expected"):
        sample_log_text(np.ones((3, 3)), 2, ("lux", "hpa"))
