"""Synthesised camera pictures of the demo scenes: each place's typical colours and layout.

Pure functions of a seeded generator: the layout (counter, court, road) stays, positions, sizes,
colours and lighting vary a little from picture to picture, and sensor noise is added, so the
dominant colours are those of the place but never exactly the same twice. BGR uint8, OpenCV's order.
"""

from __future__ import annotations

import cv2
import numpy as np

PICTURE_SIZE = (320, 240)  # width, height: a small webcam frame


def _bgr(
    rng: np.random.Generator, rgb: tuple[int, int, int], jitter: int = 12
) -> tuple[int, int, int]:
    r, g, b = (int(np.clip(c + rng.integers(-jitter, jitter + 1), 0, 255)) for c in rgb)
    return (b, g, r)


def _finish(rng: np.random.Generator, image: np.ndarray) -> np.ndarray:
    """Lighting that varies a little, and sensor noise."""
    gain = rng.uniform(0.9, 1.1)
    noisy = image.astype(np.float32) * gain + rng.normal(0, 4, image.shape)
    return np.clip(noisy, 0, 255).astype(np.uint8)


def coffee_shop(rng: np.random.Generator, size: tuple[int, int] = PICTURE_SIZE) -> np.ndarray:
    """Cream walls, a dark chalkboard menu, warm pendant lamps, a wooden counter with white cups."""
    w, h = size
    img = np.empty((h, w, 3), np.uint8)
    img[:] = _bgr(rng, (226, 206, 170))  # cream wall
    floor = int(h * rng.uniform(0.87, 0.9))
    img[floor:] = _bgr(rng, (92, 60, 38))  # dark wooden floor
    x0 = int(w * rng.uniform(0.05, 0.4))
    cv2.rectangle(
        img, (x0, int(h * 0.14)), (x0 + int(w * 0.3), int(h * 0.36)), _bgr(rng, (40, 48, 44)), -1
    )
    for _ in range(rng.integers(2, 5)):  # pendant lamps
        cx = int(rng.uniform(0.1, 0.9) * w)
        cv2.line(img, (cx, 0), (cx, int(h * 0.1)), (30, 30, 30), 1)
        cv2.circle(img, (cx, int(h * 0.13)), int(h * 0.04), _bgr(rng, (250, 200, 90)), -1)
    top = int(h * rng.uniform(0.62, 0.66))
    cv2.rectangle(img, (0, top), (w, floor), _bgr(rng, (140, 90, 52)), -1)  # the counter
    cv2.rectangle(img, (0, top), (w, top + int(h * 0.03)), _bgr(rng, (170, 118, 72)), -1)
    for _ in range(rng.integers(2, 6)):  # cups on the counter
        cx = int(rng.uniform(0.05, 0.95) * w)
        cv2.ellipse(img, (cx, top - 6), (9, 7), 0, 0, 360, _bgr(rng, (245, 243, 238), 5), -1)
    return _finish(rng, img)


def gym(rng: np.random.Generator, size: tuple[int, int] = PICTURE_SIZE) -> np.ndarray:
    """A basketball court: a maple floor with painted lines, blue walls, a backboard and its rim."""
    w, h = size
    img = np.empty((h, w, 3), np.uint8)
    img[:] = _bgr(rng, (52, 88, 150))  # painted blue wall
    horizon = int(h * rng.uniform(0.36, 0.4))
    img[horizon:] = _bgr(rng, (214, 160, 98))  # maple floor
    cv2.rectangle(img, (0, 0), (w, int(h * 0.06)), _bgr(rng, (235, 235, 230)), -1)  # hall lights
    cx = int(w * rng.uniform(0.35, 0.65))
    cv2.rectangle(
        img, (cx - 32, int(h * 0.12)), (cx + 32, int(h * 0.32)), _bgr(rng, (240, 240, 240), 5), -1
    )
    cv2.rectangle(
        img, (cx - 12, int(h * 0.22)), (cx + 12, int(h * 0.3)), _bgr(rng, (200, 40, 30)), 2
    )
    cv2.ellipse(img, (cx, int(h * 0.34)), (12, 3), 0, 0, 360, _bgr(rng, (235, 100, 20)), 2)
    paint = _bgr(rng, (175, 40, 40))  # the key, painted red
    pts = np.array([[cx - 30, horizon], [cx + 30, horizon], [cx + 50, h], [cx - 50, h]], np.int32)
    cv2.fillPoly(img, [pts], paint)
    cv2.line(img, (0, int(h * 0.8)), (w, int(h * 0.78)), (250, 250, 250), 2)
    cv2.circle(
        img,
        (int(w * rng.uniform(0.1, 0.9)), int(h * rng.uniform(0.55, 0.9))),
        7,
        _bgr(rng, (220, 100, 30)),
        -1,
    )
    return _finish(rng, img)


def street(rng: np.random.Generator, size: tuple[int, int] = PICTURE_SIZE) -> np.ndarray:
    """A street: sky, concrete and sandstone buildings, asphalt with lane markings, a parked car."""
    w, h = size
    img = np.empty((h, w, 3), np.uint8)
    img[:] = _bgr(rng, (150, 190, 228))  # sky
    x = 0
    while x < w:  # buildings along the street
        bw = int(rng.uniform(0.15, 0.3) * w)
        top = int(h * rng.uniform(0.16, 0.26))
        colour = (150, 150, 155) if rng.random() < 0.75 else (176, 160, 136)
        cv2.rectangle(img, (x, top), (x + bw, int(h * 0.52)), _bgr(rng, colour), -1)
        for wy in range(top + 8, int(h * 0.46), 16):  # windows
            for wx in range(x + 5, x + bw - 8, 14):
                cv2.rectangle(img, (wx, wy), (wx + 6, wy + 8), _bgr(rng, (70, 85, 100)), -1)
        x += bw
    road = int(h * 0.52)
    img[road:] = _bgr(rng, (88, 88, 92))  # asphalt
    cv2.rectangle(img, (0, road), (w, road + 6), _bgr(rng, (170, 170, 165)), -1)  # kerb
    for lx in range(int(rng.uniform(0, 30)), w, 50):
        cv2.rectangle(img, (lx, int(h * 0.8)), (lx + 26, int(h * 0.82)), (240, 240, 240), -1)
    cx = int(w * rng.uniform(0.1, 0.7))
    red, green, blue = (int(c) for c in rng.integers(30, 220, 3))
    car = _bgr(rng, (red, green, blue), 0)
    cv2.rectangle(img, (cx, int(h * 0.62)), (cx + 70, int(h * 0.72)), car, -1)
    cv2.circle(img, (cx + 14, int(h * 0.73)), 7, (20, 20, 20), -1)
    cv2.circle(img, (cx + 56, int(h * 0.73)), 7, (20, 20, 20), -1)
    return _finish(rng, img)


SCENE_PICTURES = {"coffee": coffee_shop, "gym": gym, "street": street}
