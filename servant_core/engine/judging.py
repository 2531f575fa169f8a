"""Judging, on the sense thread: each sense's window or picture → its prediction, the decision
pipeline's events, "What is this place?", and a decided scene → the arm.

A window that cannot be judged (unusable rows, a failing recogniser) is reported once and the
senses go on.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from servant_core.audio import SILENT_DBFS, is_silent, resample
from servant_core.engine import learning
from servant_core.engine.arm import ArmControl
from servant_core.engine.bus import EventBus
from servant_core.engine.learning import Kept
from servant_core.engine.loop import Sight
from servant_core.engine.models import Models
from servant_core.engine.unknown_places import UnknownPlaces
from servant_core.errors import ServantError
from servant_core.events import (
    AcousticPrediction,
    Decision,
    Notice,
    Palette,
    SensePrediction,
    VisualPrediction,
)
from servant_core.features.palette import dominant_colours
from servant_core.features.rows import UnusableWindow, checked_rows
from servant_core.fusion.elsewhere import beside_open_sound, shown
from servant_core.fusion.pipeline import DecisionPipeline
from servant_core.recognisers import UNKNOWN, Recogniser
from servant_core.recognisers.base import answers, knows_elsewhere, windowed
from servant_core.senses import SENSES

log = logging.getLogger(__name__)


class Judge:
    """Judges the senses' windows and pictures with `models`, feeds `decisions` (both under the
    engine's `lock`), asks about unknown places through `places` and moves the arm on a
    decision at least `confidence_threshold` percent sure (None: no threshold of its own)."""

    def __init__(
        self,
        *,
        models: Models,
        decisions: DecisionPipeline,
        places: UnknownPlaces,
        bus: EventBus,
        arm: ArmControl,
        lock: threading.RLock,
        confidence_threshold: float | None,
    ) -> None:
        self.confidence_threshold = confidence_threshold
        self._models = models
        self._decisions = decisions
        self._places = places
        self._bus = bus
        self._arm = arm
        self._lock = lock
        self._clock = bus.clock
        self._silent = False  # the last window was silence (its notice was given)
        # the predictions whose last window was skipped as unusable: told once, not each window
        self._skipping: set[str] = set()

    def guarded(self, what: str, fn: Callable[..., None], *args: Any) -> None:
        """`fn(*args)`, its failure reported (once for a run of unusable windows), not raised."""
        try:
            fn(*args)
        except UnusableWindow as error:
            if what not in self._skipping:  # one notice for a run of such windows
                self._skipping.add(what)
                self._bus.emit(Notice(self._clock(), f"{error}; more are skipped without a word"))
            return
        except ServantError as error:
            self._bus.error(str(error))
        except Exception as exc:  # e.g. a model trained on another window length: say it, go on
            log.debug("%s failed", what, exc_info=True)
            self._bus.error(f"{what} failed: {type(exc).__name__}: {exc}")
        else:
            self._skipping.discard(what)

    def forget(self) -> None:
        """A new acoustic model (or silence): what the old one believed about past windows means
        nothing (and a stretch just labelled is not asked about again). Called under `lock`."""
        self._decisions.forget()
        self._places.forget()

    def on_window(self, window: np.ndarray, rate: int) -> None:
        with self._lock:
            acoustic = self._models.acoustic
        if acoustic is None:
            return
        t = self._clock()
        if is_silent(window):
            self._on_silence(acoustic, t)
            return
        self._silent = False
        X = acoustic.featurize(resample(window, rate, windowed(acoustic).rate)[None, :])
        unit = acoustic.confidence_unit
        open_ = knows_elsewhere(acoustic)
        with self._lock:
            scene, confidence, scores = self._decisions.hear(*_predict(acoustic, X), unit, open_)
            self._decisions.note("acoustic", scores, open_)
        known = scene != UNKNOWN
        self._bus.emit(AcousticPrediction(t, scene if known else None, confidence, scores, unit))
        kept = self._places.heard(known, window, rate)
        if kept is not None:
            self._places.ask(kept, scores, t)
        self._judged("audio", scene if known else None, confidence, t, scores)

    def _on_silence(self, acoustic: Recogniser, t: float) -> None:
        """A silent window (a muted microphone, digital zeros) names no place, for the arm too:
        a recogniser asked about silence still picks a taught place. It is not asked about
        either; what the sound believed before the silence is forgotten."""
        if not self._silent:  # one notice for a run of silent windows
            self._silent = True
            self._bus.emit(
                Notice(
                    t,
                    f"microphone: silence (below {SILENT_DBFS:.0f} dBFS) names no place until "
                    "sound comes back; is the microphone muted?",
                )
            )
        scores = {str(s): 0.0 for s in acoustic.scenes_}
        with self._lock:
            self.forget()
            self._decisions.scores["acoustic"] = scores
        self._bus.emit(
            AcousticPrediction(t, None, 0.0, scores, acoustic.confidence_unit, silent=True)
        )
        self._judged("audio", None, 0.0, t, scores)

    def on_samples(self, sense: str, window: np.ndarray, rate: int) -> None:
        with self._lock:
            recogniser = self._models.samples.get(sense)
        if recogniser is None:
            return
        t = self._clock()
        rows = learning.resampled_rows(window, rate, int(windowed(recogniser).rate))
        scene, confidence, scores = _predict(recogniser, recogniser.featurize([rows]))
        known = scene != UNKNOWN
        with self._lock:
            self._decisions.note(SENSES[sense].role, scores, knows_elsewhere(recogniser))
        figure, unit = self._shown(scene if known else None, confidence, scores, recogniser)
        self._bus.emit(SensePrediction(t, sense, scene if known else None, figure, scores, unit))
        if not known and not self._places.named_elsewhere(sense, t):
            kept = Kept(sense, rows, int(windowed(recogniser).rate))
            self._places.ask(kept, scores, t)
        self._judged(sense, scene if known else None, confidence, t, scores)

    def look(self, sight: Sight | None) -> None:
        """Let the decision pipeline tick, and judge a picture from `sight` if it wants one."""
        t = self._clock()
        with self._lock:
            events = self._decisions.tick(t)
            wants = sight is not None and self._decisions.wants_picture(t)
        self.handle(events)
        self._arm.check(t)
        if not wants:
            return
        assert sight is not None
        frame = sight.grab(t)
        if frame is not None:
            self.guarded("visual prediction", self.on_picture, frame, t)

    def on_picture(self, frame: np.ndarray, t: float) -> None:
        with self._lock:
            visual = self._models.visual
        if visual is None:
            self._bus.emit(Palette(t, *dominant_colours(frame)))
            return
        X = visual.featurize([frame])
        scene, confidence, scores = _predict(visual, X)
        known = scene != UNKNOWN
        with self._lock:
            self._decisions.note("visual", scores, knows_elsewhere(visual))
            events = self._told("image", scene if known else None, confidence, t, scores)
        figure, unit = self._shown(scene if known else None, confidence, scores, visual)
        self._bus.emit(VisualPrediction(t, scene if known else None, figure, scores, unit))
        # The decision (and the arm's move) first; the palette is only for show.
        self.handle(events)
        palettes = visual.matched_palette(X)
        matched = palettes[0] if palettes is not None else None
        self._bus.emit(Palette(t, *dominant_colours(frame), scene if known else None, matched))
        if not known:
            self._places.ask(Kept("image", frame), scores, t)

    def handle(self, events: list[Any]) -> None:
        """Emit the decision pipeline's events; a decided scene, settled, goes to the arm."""
        for event in events:
            if not isinstance(event, Decision) or event.scene is None:
                self._bus.emit(event)
                continue
            scene = event.scene
            with self._lock:
                unit = decision_unit(self._models.acoustic, self._models.visual)
                event, roles = self._decisions.settle(event)
                latest = self._decisions.latest()  # one snapshot for the figure and the arm
                open_roles = set(self._decisions.open_roles)
            event = dataclasses.replace(event, confidence_unit=unit)
            self._bus.emit(event)
            if event.scene is None:
                continue
            self._arm.act(
                scene,
                latest,
                self.confidence_threshold,
                roles,
                open_roles,
                event.confidence / 100.0 if event.not_elsewhere else None,
            )

    def _judged(
        self, sense: str, scene: str | None, confidence: float, t: float, scores: dict[str, float]
    ) -> None:
        """A sense's judgement to the decision pipeline, and its events handled."""
        with self._lock:
            events = self._told(sense, scene, confidence, t, scores)
        self.handle(events)

    def _told(
        self, sense: str, scene: str | None, confidence: float, t: float, scores: dict[str, float]
    ) -> list[Any]:
        """A sense's judgement to the decision pipeline (called under `lock`)."""
        self._places.named(sense, scene, t)
        return self._decisions.tell(sense, scene, confidence, t, scores)

    def _shown(
        self, scene: str | None, confidence: float, scores: dict[str, float], recogniser: Any
    ) -> tuple[float, str | None]:
        """The figure and unit a sense's prediction is shown with (`fusion.elsewhere.shown`)."""
        with self._lock:  # the sound's model, not its last window: from the first picture on
            acoustic = self._models.acoustic
        beside = beside_open_sound(acoustic, recogniser)
        return shown(scene, confidence, recogniser.confidence_unit, scores, beside)


def decision_unit(*recognisers: Recogniser | None) -> str | None:
    """The unit of an average of these recognisers' confidences (a decision's): theirs when they
    all share one, as percentages do; else None (the paper's eq. 1 and eq. 2 share none)."""
    units = {r.confidence_unit if r is not None else None for r in recognisers}
    return units.pop() if len(units) == 1 else None


def _predict(recogniser: Recogniser, X: np.ndarray) -> tuple[str, float, dict[str, float]]:
    """(scene or UNKNOWN, confidence, {scene: probability}) for a single featurized row;
    `UnusableWindow` when the row is not finite numbers."""
    checked_rows(X, f"{recogniser.sense} prediction")
    names, confidences, probabilities = answers(recogniser, X)
    return (
        str(names[0]),
        float(confidences[0]),
        {s: float(p) for s, p in zip(recogniser.scenes_, probabilities[0], strict=True)},
    )
