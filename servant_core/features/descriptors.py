"""Dense local descriptors of a picture: gradient-orientation blocks and their colours.

A picture is centre-cropped to a square, shrunk to `size`×`size`, cut into `cell`×`cell` cells;
every 2×2 block of cells (one cell apart) gives a unit-length HOG-like histogram of `n_bins`
unsigned orientations per cell (magnitude-weighted) and its mean CIE L*a*b* colour (L 0–100, a
and b about ±100). `bovw` and `softbovw` learn their codebooks from these; beside them, a
whole-picture hue × saturation × value histogram (`hsv_histogram`).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

DEFAULT_SIZE = 128
DEFAULT_CELL = 8
DEFAULT_BINS = 9
DEFAULT_HSV_BINS = (8, 4, 4)


def square_thumbnail(image_bgr: np.ndarray, size: int = DEFAULT_SIZE) -> np.ndarray:
    """The picture's central square, resized to `size`×`size` (area averaging when shrinking)."""
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ValueError("expected a BGR picture of shape (height, width, 3)")
    h, w = image_bgr.shape[:2]
    side = min(h, w)
    top, left = (h - side) // 2, (w - side) // 2
    square = image_bgr[top : top + side, left : left + side]
    interpolation = cv2.INTER_AREA if side > size else cv2.INTER_LINEAR
    return cv2.resize(square, (size, size), interpolation=interpolation)


def cell_sums(values: np.ndarray, cell: int) -> np.ndarray:
    """Sum an (H, W, ...) array over non-overlapping cell×cell cells: (H/cell, W/cell, ...)."""
    h, w = values.shape[:2]
    return values.reshape(h // cell, cell, w // cell, cell, *values.shape[2:]).sum(axis=(1, 3))


def blocks(cells: np.ndarray) -> np.ndarray:
    """Every overlapping 2×2 block of an (R, C, d) cell grid: (R-1, C-1, 4d)."""
    return np.concatenate([cells[:-1, :-1], cells[:-1, 1:], cells[1:, :-1], cells[1:, 1:]], axis=-1)


def block_descriptors(
    image_bgr: np.ndarray,
    size: int = DEFAULT_SIZE,
    cell: int = DEFAULT_CELL,
    n_bins: int = DEFAULT_BINS,
) -> tuple[np.ndarray, np.ndarray]:
    """Per overlapping 2×2 block of cells, in row-major grid order (a block's index gives its
    place in the picture): (blocks, 4·n_bins) unit-length orientation histograms of its cells,
    and (blocks, 12) the mean L*a*b* colour of each of its four cells."""
    thumb = square_thumbnail(image_bgr, size)
    grey = cv2.cvtColor(thumb, cv2.COLOR_BGR2GRAY).astype(np.float32)
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=1)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=1)
    magnitude, angle = cv2.cartToPolar(gx, gy)
    orientation = np.minimum((angle % np.pi) / np.pi * n_bins, n_bins - 1).astype(np.intp)
    votes = np.zeros((size, size, n_bins), dtype=np.float32)
    np.put_along_axis(votes, orientation[..., None], magnitude[..., None], axis=2)
    gradient_blocks = blocks(cell_sums(votes, cell))
    gradient_blocks /= np.linalg.norm(gradient_blocks, axis=-1, keepdims=True) + 1e-6
    lab = cv2.cvtColor(thumb.astype(np.float32) / 255.0, cv2.COLOR_BGR2Lab)
    colour_blocks = blocks(cell_sums(lab, cell) / (cell * cell))
    return (
        gradient_blocks.reshape(-1, gradient_blocks.shape[-1]).astype(np.float32),
        colour_blocks.reshape(-1, colour_blocks.shape[-1]).astype(np.float32),
    )


def dense_descriptors(
    image_bgr: np.ndarray,
    size: int = DEFAULT_SIZE,
    cell: int = DEFAULT_CELL,
    n_bins: int = DEFAULT_BINS,
) -> np.ndarray:
    """(blocks, 4·n_bins + 3) float32: unit-length orientation blocks, then mean L*a*b* colour.

    Blocks are in row-major grid order, so a block's index gives its place in the picture.
    """
    gradients, colours = block_descriptors(image_bgr, size, cell, n_bins)
    mean_colour = colours.reshape(len(colours), 4, 3).mean(axis=1)
    return np.concatenate([gradients, mean_colour], axis=1)


def hsv_histogram(image_bgr: np.ndarray, bins: Sequence[int] = DEFAULT_HSV_BINS) -> np.ndarray:
    """The picture's joint hue × saturation × value histogram, as shares summing to one."""
    hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
    counts = cv2.calcHist([hsv], [0, 1, 2], None, list(bins), [0, 180, 0, 256, 0, 256]).ravel()
    return (counts / max(float(counts.sum()), 1.0)).astype(np.float32)
