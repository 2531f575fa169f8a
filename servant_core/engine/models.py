"""The recognisers the engine judges with, by sense, and their updates: a retrain on a library or
a label folded in, the learned fusion taught again, the result saved.

Every update is made on a copy (see `learning`) and swapped in under the engine's lock, so the
sense thread, which may be predicting with the old recogniser right now, never sees half of one.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from pathlib import Path

from servant_core.engine import learning
from servant_core.engine.bus import EventBus
from servant_core.engine.learning import Kept
from servant_core.errors import ServantError
from servant_core.events import Notice
from servant_core.fusion import LearnedFusion
from servant_core.fusion.pipeline import DecisionPipeline
from servant_core.library import SceneLibrary
from servant_core.recognisers import Recogniser
from servant_core.senses import SENSES


class Models:
    """The sound's (`acoustic`), the pictures' (`visual`) and each sample sense's (`samples`)
    recogniser, None (or absent) before one is fitted; one update at a time.

    `lock` is the engine's (it guards the recognisers and `decisions` together); `on_new_sound`
    is called under it when the sound's recogniser is replaced. `fresh_methods`: {sense: method}
    a retrain fits for a sense without a recogniser. `path`: the model file saved after each
    update (None: updates stay in memory). `retrain_needed`: a label was written that no
    recogniser could fold in."""

    def __init__(
        self,
        *,
        acoustic: Recogniser | None,
        visual: Recogniser | None,
        samples: Mapping[str, Recogniser],
        decisions: DecisionPipeline,
        bus: EventBus,
        lock: threading.RLock,
        fresh_methods: Mapping[str, str],
        path: Path | None,
        window_seconds: float,
        on_new_sound: Callable[[], None],
    ) -> None:
        self.acoustic = acoustic
        self.visual = visual
        self.samples = dict(samples)
        self.fresh_methods = dict(fresh_methods)
        self.path = path
        self.retrain_needed = False
        self._decisions = decisions
        self._bus = bus
        self._lock = lock
        self._update_lock = threading.Lock()
        self._window_seconds = window_seconds
        self._on_new_sound = on_new_sound

    def by_sense(self) -> dict[str, Recogniser]:
        """{sense: recogniser} for those that exist ("audio", "image", …); call under `lock`."""
        found = {"audio": self.acoustic, "image": self.visual, **self.samples}
        return {sense: model for sense, model in found.items() if model is not None}

    def untrained(self) -> bool:
        with self._lock:
            return self.acoustic is None and self.visual is None and not self.samples

    def known_scenes(self) -> list[str]:
        """The places the recognisers know, which a label may name in another case."""
        with self._lock:
            models = list(self.by_sense().values())
        return sorted({str(s) for model in models for s in model.scenes_})

    def retrain(
        self, library: SceneLibrary, on_progress: Callable[[int, int], None] | None
    ) -> list[str]:
        """Refit copies on `library` and swap them in (`Engine.retrain`); the senses retrained."""
        with self._update_lock:
            with self._lock:
                current = self.by_sense()
            fitted, failures = learning.retrained(
                library,
                current,
                self.fresh_methods,
                self._window_seconds,
                self._report_error,
                on_progress,
            )
            if not fitted:
                if failures:
                    raise failures[0]
                return []
            for failure in failures:
                self._report_error(failure)
            with self._lock:
                for sense, model in fitted.items():
                    self._swap(sense, model)
                self.retrain_needed = False
            self._relearn_fusion(library)
            self._save()
        return list(fitted)

    def fold_in(self, kept: Kept, scene: str) -> None:
        """Fold the labelled `kept` into a copy of its sense's recogniser and swap it in, if
        that recogniser `folds_in`; otherwise `retrain_needed` becomes True."""
        with self._update_lock:
            with self._lock:
                recogniser = self.by_sense().get(kept.sense)
                if recogniser is None or not recogniser.folds_in:
                    self.retrain_needed = True
                    return
            model = learning.folded_in(recogniser, kept, scene)
            with self._lock:
                self._swap(kept.sense, model)
            self._save()

    def _swap(self, sense: str, model: Recogniser) -> None:
        """Use `model` for `sense` from now on (called under `lock`)."""
        if sense == "audio":
            self.acoustic = model
            self._on_new_sound()
        elif sense == "image":
            self.visual = model
        else:
            self.samples[sense] = model

    def _relearn_fusion(self, library: SceneLibrary) -> None:
        """The learned policy's net, taught again on the retrained recognisers (called under
        `_update_lock`); too little taught, the parallel policy decides meanwhile, and a Notice
        says why. The rule policies learn nothing."""
        with self._lock:
            if not isinstance(self._decisions.policy, LearnedFusion):
                return
            recognisers = self.by_sense()
        net, why = learning.library_fusion_net(
            library, recognisers, self._window_seconds, self._report_error
        )
        clock = self._bus.clock
        with self._lock:
            self._decisions.policy = LearnedFusion(self._decisions.policy.config, net)
            state = self._decisions.policy.state(clock())
        self._bus.emit(state)
        if net is None:
            self._bus.emit(Notice(clock(), f"learned fusion: {why}; the parallel policy decides"))

    def _save(self) -> None:
        """Write the current recognisers to `path` (called under `_update_lock`)."""
        if self.path is None:
            return
        with self._lock:
            models = {"acoustic": self.acoustic, "visual": self.visual}
            models.update({SENSES[s].role: m for s, m in self.samples.items()})
            policy = self._decisions.policy
            net = policy.net if isinstance(policy, LearnedFusion) else None
        learning.save_models(self.path, models, self._report_error, net)

    def _report_error(self, error: ServantError) -> None:
        self._bus.error(str(error))
