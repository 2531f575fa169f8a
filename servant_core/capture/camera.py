"""The camera, through OpenCV's `VideoCapture`: a device index, a video file, or an image sequence.

Frames are grabbed on demand, when the fusion policy asks for a picture, not streamed. A video
file or image sequence stands in for a camera (that is how tests drive the real capture path);
at its end it starts again from the first frame, as a camera never runs out.
"""

from __future__ import annotations

import os
import stat

import cv2
import numpy as np

from servant_core.errors import ServantError

# OpenCV's own warnings ("can't open camera by index") go straight to the terminal, over the
# application's screen; a camera that cannot be opened is said in one line of ours instead.
cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
# FFmpeg's own log (AV_LOG_QUIET, -8) likewise: "[image2 @ 0x…] Could find no file or sequence"
# landed on the app's screen when an image sequence could not be opened. OpenCV reads it at the
# first FFmpeg open; a value the user set is kept.
os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")


def parse_camera(spec: int | str) -> int | str:
    """ "0" is camera index 0; anything else is a video file or image pattern (img_%03d.png)."""
    if isinstance(spec, str) and spec.strip().isdigit():
        return int(spec)
    return spec


# V4L2 allows 64 devices a driver; OpenCV takes the index as a C int (and fails on more).
MAX_CAMERA_INDEX = 1023
V4L2_MAJOR = 81  # Linux's video4linux devices (/dev/video*)


def _check_video_path(source: str) -> None:
    """A video file must be a regular file (a FIFO would block OpenCV forever, ignoring any
    time limit, and a device like /dev/zero reads without end); a camera device path must be
    a video device. A path that does not exist may be an image pattern (img_%03d.png)."""
    try:
        info = os.stat(source)
    except (OSError, ValueError):
        return
    if stat.S_ISREG(info.st_mode):
        return
    if stat.S_ISCHR(info.st_mode) and os.major(info.st_rdev) == V4L2_MAJOR:
        return
    raise ServantError(
        f"video {source}: not a video file nor a camera device; give a video file, an image "
        "pattern or a camera index (Settings, or --camera)"
    )


class Camera:
    def __init__(self, source: int | str = 0) -> None:
        self.source = parse_camera(source)
        kind = "camera" if isinstance(self.source, int) else "video"
        self.name = f"{kind} {self.source}"
        self._capture: cv2.VideoCapture | None = None

    @property
    def is_file(self) -> bool:
        return not isinstance(self.source, int)

    def open(self) -> None:
        self.close()
        if isinstance(self.source, int) and not 0 <= self.source <= MAX_CAMERA_INDEX:
            raise ServantError(
                f"{self.name}: no such camera; a camera index is 0 to {MAX_CAMERA_INDEX}"
            )
        if isinstance(self.source, str):
            _check_video_path(self.source)
        capture = cv2.VideoCapture(self.source)
        if not capture.isOpened():
            capture.release()
            what = (
                "no such camera" if not self.is_file else "cannot open this video or image sequence"
            )
            raise ServantError(
                f"{self.name}: {what}; check the index or path (Settings, or --camera)"
            )
        self._capture = capture

    def read(self) -> np.ndarray:
        if self._capture is None:
            self.open()
        assert self._capture is not None
        ok, frame = self._capture.read()
        if not ok and self.is_file:
            self._capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, frame = self._capture.read()
        if not ok or frame is None:
            raise ServantError(f"{self.name}: returned no frame (unplugged or busy?); reopening it")
        if frame.ndim == 2:
            frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        return frame

    def close(self) -> None:
        capture, self._capture = self._capture, None
        if capture is not None:
            capture.release()
