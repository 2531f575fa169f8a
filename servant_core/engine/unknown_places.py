"""The unknown-place state: when the wearer is asked "What is this place?", what a label is for,
and writing it into the library.

Folding a label into a recogniser is `models.Models.fold_in`; this part only keeps and writes.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from servant_core.engine import learning
from servant_core.engine.bus import EventBus
from servant_core.engine.learning import Kept, Unknowns
from servant_core.events import UnknownScene
from servant_core.place_names import place_name


class UnknownPlaces:
    """The unknown windows, pictures and sample windows kept for a label (`store`), the sound's
    stretch of windows that named no taught place, and each sense's last named place.

    The wearer is asked about the sound once it has named no taught place for `ask_after_s`
    (a whole stretch of `window_seconds` windows), about a picture or a sample sense's window at
    once (a sample sense only when no other sense named a place within two windows)."""

    def __init__(self, bus: EventBus, *, ask_after_s: float, window_seconds: float) -> None:
        self.store = Unknowns()
        self._bus = bus
        self._window_seconds = window_seconds
        self._lock = threading.Lock()
        # the sound's last windows (and their rates) while it names no taught place, up to
        # `ask_after_s` of them: when "What is this place?" is asked and what its label is for
        self._stretch: deque[tuple[np.ndarray, int]] = deque(
            maxlen=max(1, round(ask_after_s / window_seconds))
        )
        # Each sense's last opinion: (when, the scene it named or None).
        self._last_named: dict[str, tuple[float, str | None]] = {}

    def heard(self, known: bool, window: np.ndarray, rate: int) -> Kept | None:
        """The sound's window to ask about, once the sound has named no taught place for
        `ask_after_s` (this window included), and at each window while it holds (the app limits
        how often the question is shown); else None. The label the wearer gives is for the whole
        stretch, not the last 5 s alone, so the place is learned from as much as teach mode asks
        for (`TEACH_WINDOWS`, 30 s)."""
        with self._lock:
            if known:
                self._stretch.clear()
                return None
            self._stretch.append((window, rate))
            if len(self._stretch) != self._stretch.maxlen:
                return None
            before = tuple(w for w, r in list(self._stretch)[:-1] if r == rate)
        return Kept("audio", window, rate, before)

    def forget(self) -> None:
        """A new sound model, or silence: the stretch so far is not asked about."""
        with self._lock:
            self._stretch.clear()

    def named(self, sense: str, scene: str | None, t: float) -> None:
        """What `sense` named at `t` (None: no taught place)."""
        with self._lock:
            self._last_named[sense] = (t, scene)

    def named_elsewhere(self, sense: str, t: float) -> bool:
        """Whether another sense named a place within the last two windows. A sample sense
        (motion, ambient) that does not know a place the sound or the camera knows is not
        worth asking the wearer about: they know where they are, and so does Servant."""
        recent = t - 2 * self._window_seconds
        with self._lock:
            named = list(self._last_named.items())
        return any(other != sense and scene and when >= recent for other, (when, scene) in named)

    def ask(self, kept: Kept, scores: dict[str, float], t: float) -> None:
        """Keep `kept` for a label and ask "What is this place?" (`UnknownScene`)."""
        window_id = self.store.keep(kept)
        nearest = max(scores, key=lambda s: scores[s]) if scores else None
        self._bus.emit(UnknownScene(t, kept.sense, nearest, window_id))

    def write_label(
        self, window_id: str, scene: str, root: Path, known_scenes: Iterable[str]
    ) -> tuple[Kept, str, Path]:
        """Write the kept window `window_id` into the library as `scene` (`root/<scene>/`,
        atomically): (the window, the place's name as written, the file). The name must pass
        `place_names.place_name` (one naming a known place in another case is that place). A
        refused name or a failed write is one ServantError, and the window can still be
        labelled."""
        scene = place_name(scene, root, known_scenes)
        # out of the store only once written: a label whose write fails can be given again
        with self.store.labelling(window_id) as kept:
            path = learning.write_labelled(root, scene, window_id, kept)
        return kept, scene, path
