"""Dense SIFT: SIFT descriptors on a regular grid of a picture, at a few scales (pure functions).

VLFeat's `dsift` shortcut: gradients binned once into 8 orientation channels, each pooled once with
SIFT's bilinear cell weighting, every patch's 4×4 cells read off the pooled maps (a Gaussian weight
per cell, not per pixel). A picture is centre-cropped to a square of `size`×`size` pixels; for each
cell width `b` in `bin_sizes` patches are 4b pixels wide, one every `step` pixels. Descriptors are
SIFT-normalised (unit length, clipped at 0.2, unit length) then RootSIFT (L1, square root).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from servant_core.features.descriptors import square_thumbnail

N_ORIENTATIONS = 8
N_CELLS = 4  # a patch is N_CELLS × N_CELLS cells
SIFT_DIM = N_CELLS * N_CELLS * N_ORIENTATIONS
DEFAULT_SIFT_SIZE = 128
DEFAULT_BIN_SIZES = (4, 6)
DEFAULT_STEP = 6
CLIP = 0.2
# VLFeat's PHOW smooths the picture by bin size / 6 before taking gradients
MAGNIFICATION = 6.0


def grid_centres(size: int, bin_size: int, step: int) -> np.ndarray:
    """Patch centres along one axis: every `step` pixels, each 4·`bin_size`-wide patch inside
    the picture; the grid is centred, so that mirroring the picture nearly maps it onto itself."""
    half = N_CELLS * bin_size // 2
    if size < 2 * half:
        raise ValueError(f"a {size}-pixel picture has no room for {2 * half}-pixel patches")
    count = (size - 2 * half) // step + 1
    first = half + (size - 2 * half - (count - 1) * step) // 2
    return first + step * np.arange(count)


def keypoint_positions(size: int, bin_sizes: Sequence[int], step: int) -> np.ndarray:
    """(n, 2) each patch's centre (x, y) as a fraction of the picture's width, in the order
    `dense_root_sift` lists the patches: per bin size, row-major."""
    positions = []
    for b in bin_sizes:
        c = (grid_centres(size, b, step) + 0.5) / size
        y, x = np.meshgrid(c, c, indexing="ij")
        positions.append(np.stack([x.ravel(), y.ravel()], axis=1))
    return np.concatenate(positions).astype(np.float32)


def orientation_channels(grey: np.ndarray) -> np.ndarray:
    """(H, W, 8) gradient magnitude split between the two nearest of 8 orientations (bin k at
    k·45°, over the full circle as SIFT has it)."""
    gx = cv2.Sobel(grey, cv2.CV_32F, 1, 0, ksize=1)
    gy = cv2.Sobel(grey, cv2.CV_32F, 0, 1, ksize=1)
    magnitude, angle = cv2.cartToPolar(gx, gy)
    position = angle * (N_ORIENTATIONS / (2 * np.pi))
    low = np.floor(position)
    upper_share = position - low
    k = low.astype(np.intp) % N_ORIENTATIONS
    channels = np.zeros((*grey.shape, N_ORIENTATIONS), dtype=np.float32)
    np.put_along_axis(channels, k[..., None], (magnitude * (1 - upper_share))[..., None], axis=2)
    np.put_along_axis(
        channels,
        ((k + 1) % N_ORIENTATIONS)[..., None],
        (magnitude * upper_share)[..., None],
        axis=2,
    )
    return channels


def cell_weights() -> np.ndarray:
    """(4, 4) SIFT's Gaussian window (σ = half the patch) at each cell's centre."""
    offsets = np.arange(N_CELLS) - (N_CELLS - 1) / 2
    sigma = N_CELLS / 2
    return np.exp(-(offsets[:, None] ** 2 + offsets[None, :] ** 2) / (2 * sigma**2))


def dense_sift(grey: np.ndarray, bin_size: int, step: int) -> np.ndarray:
    """(n, 128) SIFT descriptors (unit length, clipped, unit length) of a square float32 grey
    picture on the grid of `grid_centres`, row-major; a flat patch gives zeros."""
    sigma = bin_size / MAGNIFICATION
    smoothed = cv2.GaussianBlur(grey, (0, 0), sigma) if sigma > 0 else grey
    channels = orientation_channels(smoothed)
    triangle = 1.0 - np.abs(np.arange(-bin_size + 1, bin_size)) / bin_size
    triangle = (triangle / triangle.sum()).astype(np.float32)
    pooled = np.stack(
        [cv2.sepFilter2D(channels[..., o], -1, triangle, triangle) for o in range(N_ORIENTATIONS)],
        axis=-1,
    )
    centres = grid_centres(grey.shape[0], bin_size, step)
    cells = np.rint(centres[:, None] + (np.arange(N_CELLS) - 1.5) * bin_size).astype(np.intp)
    # (rows, cols, cell row, cell col, orientation)
    patches = pooled[cells[:, None, :, None], cells[None, :, None, :]]
    patches = patches * cell_weights()[None, None, :, :, None].astype(np.float32)
    return sift_normalised(patches.reshape(-1, SIFT_DIM))


def sift_normalised(descriptors: np.ndarray) -> np.ndarray:
    """SIFT's normalisation: unit length, each value clipped at 0.2, unit length again."""
    unit = descriptors / (np.linalg.norm(descriptors, axis=1, keepdims=True) + 1e-7)
    clipped = np.minimum(unit, CLIP)
    return clipped / (np.linalg.norm(clipped, axis=1, keepdims=True) + 1e-7)


def root_sift(descriptors: np.ndarray) -> np.ndarray:
    """RootSIFT: each (non-negative) descriptor divided by its sum, then square-rooted."""
    total = descriptors.sum(axis=1, keepdims=True)
    return np.sqrt(descriptors / np.where(total > 0, total, 1.0))


def dense_root_sift(
    image_bgr: np.ndarray,
    size: int = DEFAULT_SIFT_SIZE,
    bin_sizes: Sequence[int] = DEFAULT_BIN_SIZES,
    step: int = DEFAULT_STEP,
) -> np.ndarray:
    """(n, 128) float32 RootSIFT descriptors of the picture's central square, every bin size's
    grid in turn (see `keypoint_positions` for where each patch lies)."""
    thumb = square_thumbnail(image_bgr, size)
    grey = cv2.cvtColor(thumb, cv2.COLOR_BGR2GRAY).astype(np.float32) / 255.0
    return np.concatenate([root_sift(dense_sift(grey, b, step)) for b in bin_sizes]).astype(
        np.float32
    )


def mirror_order(size: int, bin_sizes: Sequence[int], step: int) -> tuple[np.ndarray, np.ndarray]:
    """How the left-right mirror image's descriptors follow from the picture's: (patches,
    dims) index arrays, `mirrored = descriptors[patches][:, dims]`. Mirroring reverses each
    grid's columns, each patch's cell columns, and turns orientation θ into π − θ (bin k into
    bin 4 − k). Exact up to the grid's rounding (at most a pixel off centre)."""
    patches = []
    start = 0
    for b in bin_sizes:
        n = len(grid_centres(size, b, step))
        patches.append(start + np.arange(n * n).reshape(n, n)[:, ::-1].ravel())
        start += n * n
    orientation = (N_ORIENTATIONS // 2 - np.arange(N_ORIENTATIONS)) % N_ORIENTATIONS
    dims = (
        np.arange(SIFT_DIM)
        .reshape(N_CELLS, N_CELLS, N_ORIENTATIONS)[:, ::-1][:, :, orientation]
        .ravel()
    )
    return np.concatenate(patches), dims
