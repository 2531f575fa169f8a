"""Choosing a head's regularisation for the probabilities it gives, not only for its ranking.

A picture's figure (`× average`, `fusion/elsewhere.likelier`) and its weight in the decision are
its head's probabilities, so the regularisation is chosen by the log loss of pictures held out
of the training pictures. Balanced accuracy, the earlier criterion, cannot choose: with six
pictures a place every setting of the grid ranks the places alike, and the simplest (the
flattest probabilities: every picture about 1.0× average) was taken.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from sklearn.model_selection import StratifiedKFold


def held_out_losses(log_proba: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(n,) each held-out row's log loss, −log p of its true column, weighted so that every
    class counts alike (as the head's balanced class weights do): a row of a class with c
    rows of n among K classes weighs n / (K·c), so the weights average one (pure)."""
    truth = np.asarray(truth, dtype=np.intp)
    classes, index, counts = np.unique(truth, return_inverse=True, return_counts=True)
    weights = len(truth) / (len(classes) * counts[index])
    return -weights * np.asarray(log_proba)[np.arange(len(truth)), truth]


def least_regularised_within_error(losses: np.ndarray) -> int:
    """Of (settings, rows) held-out losses, settings ordered most regularised first: the last
    setting whose mean loss is within one standard error (of the best setting's rows) of the
    best mean. Toward less regularisation, because the head that is kept learns from every
    training picture, more than each fold's head did, and can afford it (pure)."""
    means = losses.mean(axis=1)
    best = int(np.argmin(means))
    error = losses[best].std(ddof=1) / np.sqrt(losses.shape[1]) if losses.shape[1] > 1 else 0.0
    return int(np.flatnonzero(means <= means[best] + error)[-1])


def settings_losses(
    labels: np.ndarray,
    n_settings: int,
    fold_log_proba: Callable[[np.ndarray, np.ndarray], np.ndarray],
    max_folds: int,
    random_state: int | None,
) -> np.ndarray | None:
    """(settings, rows) held-out losses (`held_out_losses`) of every setting for every row of
    `labels`, held out in stratified folds (at most `max_folds`, at most the fewest rows of a
    label); `fold_log_proba(train, test)` gives (settings, len(test), labels) log probabilities
    of the test rows by heads learned on the train rows. None with fewer than two folds."""
    classes = np.unique(labels)
    folds = min(max_folds, int(min(np.unique(labels, return_counts=True)[1])))
    if folds < 2 or len(classes) < 2:
        return None
    log_proba = np.zeros((n_settings, len(labels), len(classes)))
    cv = StratifiedKFold(folds, shuffle=True, random_state=random_state)
    for train, test in cv.split(labels, labels):
        log_proba[:, test] = fold_log_proba(train, test)
    truth = np.searchsorted(classes, labels)
    return np.array([held_out_losses(p, truth) for p in log_proba])
