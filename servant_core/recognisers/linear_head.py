"""What recognisers with a linear head and a novelty head do once fitted.

A recogniser that maps windows or pictures into a space of its own (`_space(X)`), fits a
probabilistic head there (`_proba(D)`; by default `head_`, a scikit-learn classifier) and one
centroid per scene with its spread (`novelty_head_`, `SceneCentroids`) answers every question the
same way: this mixin (`softbovw`, `fisher-bovw`, and `kmeans-encoder`, whose head is its own
tempered softmax).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar, Self

import numpy as np
from sklearn.exceptions import NotFittedError

from servant_core.recognisers.base import UNKNOWN, Capabilities, elsewhere_unnamed
from servant_core.recognisers.centroids import SceneCentroids


class LinearHeadAnswers(Capabilities):
    head_: Any
    novelty_head_: SceneCentroids
    # each folds a label into both heads
    folds_in: ClassVar[bool] = True

    def _space(self, X: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def fold_in(self, X: np.ndarray, scenes: Sequence[str]) -> Self:
        raise NotImplementedError

    @property
    def scenes_(self) -> list[str]:
        self._check_fitted()
        return [str(s) for s in self.head_.classes_]

    def _check_fitted(self) -> None:
        if not hasattr(self, "head_"):
            raise NotFittedError(f"this {type(self).__name__} is not fitted yet; call fit first")

    def _proba(self, D: np.ndarray) -> np.ndarray:
        return np.asarray(self.head_.predict_proba(D))

    @property
    def knows_elsewhere(self) -> bool:
        """Whether `open_proba` leaves room for somewhere else (a head with a background)."""
        return False

    def _open_proba(self, D: np.ndarray) -> np.ndarray:
        """The probability of each taught place and not somewhere else: a head that knows no
        somewhere else (no background) has only the shares among the taught places."""
        return self._proba(D)

    def predict_proba(self, X: np.ndarray) -> np.ndarray:
        return self._proba(self._space(X))

    def open_proba(self, X: np.ndarray) -> np.ndarray:
        """(n, scenes) rows summing to at most one; the rest is the probability that the window
        or picture comes from a place not taught."""
        return self._open_proba(self._space(X))

    def predict(self, X: np.ndarray) -> np.ndarray:
        """The likeliest taught place; `UNKNOWN` where the row is far from every place taught
        (the novelty head). Whether it is more likely somewhere else: `open_predict`."""
        return self._names(self._space(X)).astype(str)

    def _names(self, D: np.ndarray) -> np.ndarray:
        names = np.asarray(self.scenes_, dtype=object)[np.argmax(self._proba(D), axis=1)]
        names[self.novelty_head_.is_unknown(D)] = UNKNOWN
        return names

    def answers(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """`open_predict`, `confidence` and `open_probabilities` of the same rows, from one trip
        into the space: the trip is most of what a window or a picture costs, and the live engine
        asks all three of each."""
        D = self._space(X)
        open_p = np.asarray(self._open_proba(D), dtype=float)
        names = self._names(D)
        if self.knows_elsewhere:
            names = elsewhere_unnamed(names, open_p)
            names[self._unlike_taught(D, names)] = UNKNOWN
        return names.astype(str), 100.0 * np.max(open_p, axis=1), open_p

    def _unlike_taught(self, D: np.ndarray, names: np.ndarray) -> np.ndarray:
        """(n,) bool: rows unlike every row their named place was taught on (a recogniser's
        own acceptance check; none by default)."""
        return np.zeros(len(D), dtype=bool)

    def confidence(self, X: np.ndarray) -> np.ndarray:
        """The probability of the likeliest taught place and not somewhere else, in percent."""
        return 100.0 * np.max(self.open_proba(X), axis=1)

    def novelty(self, X: np.ndarray) -> np.ndarray:
        """Distance to the nearest scene centroid in its spreads, over the rejection distance:
        above 1 a window or picture is unknown."""
        D = self._space(X)
        return self.novelty_head_.nearest_scaled(D) / self.novelty_head_.reject_distance
