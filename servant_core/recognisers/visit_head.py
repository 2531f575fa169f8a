"""`kmeans-encoder`'s head as pure functions: a multinomial logistic regression with one class a
visit of a place and one for somewhere else (`<elsewhere>`), read through a tempered softmax and
pooled back into places (`kmeans_encoder`'s module docstring, 4, 7 and 8)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from sklearn.linear_model import LogisticRegression


class VisitHead(NamedTuple):
    """A fitted head: each visit's place (`mode_scenes`), the places sorted (`classes`), each
    visit's weights over the descriptors and `<elsewhere>`'s (none without a background)."""

    mode_scenes: np.ndarray
    classes: list[str]
    coef: np.ndarray
    intercept: np.ndarray
    elsewhere_coef: np.ndarray
    elsewhere_intercept: np.ndarray


def fit_visit_head(
    rows: np.ndarray,
    scenes: np.ndarray,
    visits: np.ndarray,
    background: np.ndarray,
    column_weights: np.ndarray,
    *,
    C: float,
    elsewhere_weight: float,
) -> VisitHead:
    """The head over standardised descriptor `rows` of `scenes`' `visits` and the `background`'s
    rows, each column scaled by `column_weights` while fitting, the weights then folded back
    into the coefficients: the head reads standardised descriptors."""
    # One class a visit of a place, every visit weighing alike whatever its number of windows,
    # and the background (`<elsewhere>`) as much as one place's visits on average. With one
    # visit a place these are scikit-learn's balanced class weights.
    keys, modes = np.unique(np.stack([scenes, visits], axis=1), axis=0, return_inverse=True)
    modes = modes.reshape(-1)
    mode_scenes = keys[:, 0].astype(str)
    n_modes = len(keys)
    classes = sorted(set(mode_scenes.tolist()))
    labels = np.concatenate([modes, np.full(len(background), n_modes)])
    counts = np.bincount(labels, minlength=n_modes + 1)
    share = np.ones(n_modes + 1)
    share[n_modes] = elsewhere_weight * n_modes / len(classes)
    n_classes = n_modes + int(counts[n_modes] > 0)
    sample_weight = share[labels] / counts[labels] * len(labels) / n_classes
    head = LogisticRegression(C=C, max_iter=3000)
    head.fit(np.vstack([rows, background]) * column_weights, labels, sample_weight=sample_weight)
    coef, intercept = head.coef_ * column_weights, head.intercept_
    if len(head.classes_) == 2:  # scikit-learn keeps one weight vector for two classes
        coef = np.vstack([-coef / 2, coef / 2])
        intercept = np.array([-intercept[0] / 2, intercept[0] / 2])
    return VisitHead(
        mode_scenes,
        classes,
        coef[:n_modes],
        intercept[:n_modes],
        coef[n_modes:].reshape(-1, coef.shape[1]),
        intercept[n_modes:],
    )


def softmax_proba(scores: np.ndarray) -> np.ndarray:
    scores = scores - scores.max(axis=1, keepdims=True)
    e = np.exp(scores)
    return e / e.sum(axis=1, keepdims=True)


def place_proba(
    mode_proba: np.ndarray, mode_scenes: np.ndarray, places: list[str], together: bool = False
) -> np.ndarray:
    """(n, places): each place's likeliest visit's probability, or all its visits' together."""
    pool = np.sum if together else np.max
    return np.stack([pool(mode_proba[:, mode_scenes == place], axis=1) for place in places], axis=1)
