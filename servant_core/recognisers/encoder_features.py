"""How `kmeans-encoder` describes a window, as pure functions: each band's frame statistics, the
triangle encoding of the frames against a codebook, and the equalised and cropped copies of the
training windows (`kmeans_encoder`'s module docstring, 2, 3 and 5)."""

from __future__ import annotations

import numpy as np


def frame_statistics(frames: np.ndarray) -> np.ndarray:
    """(n, 3·bands): per band, the mean and std over frames and the std of its frame-to-frame
    change, of (n, frames, bands) log-mel windows."""
    change = np.diff(frames, axis=1)
    return np.concatenate([frames.mean(axis=1), frames.std(axis=1), change.std(axis=1)], axis=1)


def triangle_encoding(frames: np.ndarray, codewords: np.ndarray) -> np.ndarray:
    """(n, K): the triangle activations max(0, mean_k z − z_k) of each frame, where z_k is its
    distance to codeword k, averaged over each window's frames (Coates, Lee & Ng 2011)."""
    n, t, d = frames.shape
    flat = frames.reshape(-1, d).astype(np.float32)
    squared = (
        np.sum(flat**2, axis=1, keepdims=True)
        - 2.0 * flat @ codewords.T
        + np.sum(codewords**2, axis=1)[None, :]
    )
    z = np.sqrt(np.maximum(squared, 0.0))
    active = np.maximum(0.0, z.mean(axis=1, keepdims=True) - z)
    return active.reshape(n, t, -1).mean(axis=1)


def eq_curves(bands: int, strength: float, n: int) -> np.ndarray:
    """(n, bands) equaliser curves in log10 units, each with zero mean (the level is kept): a tilt
    and a bend of the log spectrum, `strength` at the band edges, their mix turned evenly around
    the circle. Evenly spaced, not drawn at random: the fitted model does not depend on the
    draw, which is what made the few-shot figures swing from one random state to the next."""
    x = np.linspace(-1.0, 1.0, bands)
    angles = np.pi / 4 + 2.0 * np.pi * np.arange(n) / n
    curves = strength * (np.cos(angles)[:, None] * x + np.sin(angles)[:, None] * (x**2 - 1 / 3))
    return curves - curves.mean(axis=1, keepdims=True)


def equalised(frames: np.ndarray, curve: np.ndarray) -> np.ndarray:
    """`frames` (…, bands) through one equaliser curve (bands,): how another microphone would
    colour the same place."""
    return (frames + curve).astype(np.float32)


def window_crops(frames: np.ndarray, crops: int, fraction: float) -> list[np.ndarray]:
    """`crops` evenly spaced parts of (n, frames, bands) windows, each `fraction` of a window long:
    with a window or two a scene (a first teach session) the head still sees how a place varies
    within itself."""
    length = max(2, int(round(frames.shape[1] * fraction)))
    starts = np.linspace(0, frames.shape[1] - length, crops).astype(int)
    return [frames[:, s : s + length] for s in starts]
