"""Replay recordings and pictures as if they were live, at real speed or as fast as possible.

`PacedAudio` plays a sequence of clips block by block. At real speed it sleeps so that blocks
arrive when a microphone would deliver them; as fast as possible it never sleeps and advances a
`ManualClock` by each block's duration instead, so the engine's event times are stream times.
`replay_recordings` feeds it from audio files (a corrupt one is reported and skipped), and
`PictureReplay` shows pictures of whichever scene the audio is playing.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servant_core.audio import DEFAULT_RATE, read_audio
from servant_core.capture.source import ManualClock
from servant_core.errors import ServantError
from servant_core.library import Picture, Recording, read_picture

DEFAULT_BLOCK_SECONDS = 0.02


@dataclass(frozen=True)
class Clip:
    """A stretch of mono audio and what it is (its scene, or a file name)."""

    label: str | None
    samples: np.ndarray


class PacedAudio:
    """An audio source over clips; an item that is a ServantError is raised once by `read`.

    `current_label` is the label of the clip the last block came from.
    """

    def __init__(
        self,
        clips: Iterable[Clip | ServantError],
        rate: int,
        *,
        realtime: bool = True,
        clock: ManualClock | None = None,
        block_seconds: float = DEFAULT_BLOCK_SECONDS,
        name: str = "replay",
    ) -> None:
        self.name = name
        self.rate = rate
        self.live = False
        self.rate_note: str | None = None  # a replay plays at the rate it is given
        self.realtime = realtime
        self.clock = clock
        self.block = max(1, int(round(rate * block_seconds)))
        self.current_label: str | None = None
        self._clips: Iterator[Clip | ServantError] = iter(clips)
        self._clip: Clip | None = None
        self._offset = 0
        self._produced = 0
        self._started_at: float | None = None
        self._exhausted = False

    def open(self) -> None:
        self._started_at = None

    @property
    def exhausted(self) -> bool:
        return self._exhausted

    def _next_clip(self) -> Clip | None:
        while self._clip is None or self._offset >= len(self._clip.samples):
            item = next(self._clips, None)
            if item is None:
                self._exhausted = True
                return None
            if isinstance(item, ServantError):
                raise item
            self._clip, self._offset = item, 0
        return self._clip

    def read(self, timeout: float) -> np.ndarray | None:
        if self.realtime:
            now = time.monotonic()
            if self._started_at is None:
                self._started_at = now
            due = self._started_at + (self._produced + self.block) / self.rate
            if due > now:
                time.sleep(min(due - now, timeout))
                if time.monotonic() < due:
                    return None
        clip = self._next_clip()
        if clip is None:
            if self.realtime:
                time.sleep(timeout)
            return None
        block = clip.samples[self._offset : self._offset + self.block]
        self._offset += len(block)
        self._produced += len(block)
        self.current_label = clip.label
        if self.clock is not None:
            self.clock.advance(len(block) / self.rate)
        return block

    def close(self) -> None:
        self._exhausted = True


def recording_clips(
    recordings: Sequence[Recording], rate: int, loop: bool = False
) -> Iterator[Clip | ServantError]:
    """Decode each recording in turn (only one in memory); a bad one yields its ServantError."""
    if not recordings:
        return
    for recording in itertools.cycle(recordings) if loop else recordings:
        try:
            yield Clip(recording.scene, read_audio(recording.path, rate))
        except ServantError as error:
            yield error


def replay_recordings(
    recordings: Sequence[Recording] | Sequence[str | Path],
    rate: int = DEFAULT_RATE,
    *,
    realtime: bool = True,
    clock: ManualClock | None = None,
    loop: bool = False,
    block_seconds: float = DEFAULT_BLOCK_SECONDS,
) -> PacedAudio:
    """An audio source that plays recordings (or plain paths) one after another at `rate`."""
    items = [
        r if isinstance(r, Recording) else Recording(Path(r).stem, Path(r)) for r in recordings
    ]
    name = (
        f"replay {items[0].path.name}" if len(items) == 1 else f"replay of {len(items)} recordings"
    )
    return PacedAudio(
        recording_clips(items, rate, loop),
        rate,
        realtime=realtime,
        clock=clock,
        block_seconds=block_seconds,
        name=name,
    )


class PictureReplay:
    """A frame source cycling through pictures; with `scene_of`, only pictures of that scene.

    `scene_of()` names the scene being heard (e.g. `PacedAudio.current_label`); a scene with no
    picture, or None, falls back to all pictures. An unreadable picture raises its ServantError
    once and is then left out.
    """

    def __init__(
        self, pictures: Sequence[Picture], scene_of: Callable[[], str | None] | None = None
    ) -> None:
        self.name = "picture replay"
        self.pictures = list(pictures)
        self.scene_of = scene_of
        self._turn: dict[str | None, int] = {}

    def open(self) -> None:
        if not self.pictures:
            raise ServantError(
                f"{self.name}: no pictures to show; add PNG or JPEG files to the library"
            )

    def read(self) -> np.ndarray:
        scene = self.scene_of() if self.scene_of else None
        pool = [p for p in self.pictures if p.scene == scene] or self.pictures
        if not pool:
            raise ServantError(f"{self.name}: no readable picture left")
        turn = self._turn.get(scene, 0)
        self._turn[scene] = turn + 1
        picture = pool[turn % len(pool)]
        try:
            return read_picture(picture.path)
        except ServantError:
            self.pictures.remove(picture)
            raise

    def close(self) -> None:
        pass
