"""Modulation spectra of log-mel frames: small exact cases."""

from __future__ import annotations

import numpy as np

from servant_core.features.logmel import frame_rate
from servant_core.features.modulation import MODULATION_FLOOR, band_groups, modulation_spectrum

RATE = 22050 / 512


def test_frame_rate_of_half_overlapping_frames() -> None:
    assert frame_rate(22050, 0.046) == 22050 / 512  # a 1024-point FFT, hop 512
    assert frame_rate(44100, 0.046) == 44100 / 1024


def test_band_groups_average_contiguous_bands() -> None:
    frames = np.arange(6, dtype=np.float32).reshape(1, 1, 6)
    np.testing.assert_allclose(band_groups(frames, 2), [[[1.0, 4.0]]])
    np.testing.assert_allclose(band_groups(frames, 3), [[[0.5, 2.5, 4.5]]])


def envelope_windows(hz: float, frames: int = 214, bands: int = 8) -> np.ndarray:
    t = np.arange(frames) / RATE
    return np.repeat(0.5 * np.sin(2 * np.pi * hz * t)[None, :, None], bands, axis=2)


def test_a_rhythm_lands_in_its_bin() -> None:
    """A band group whose log energy swings 3 times a second peaks in the 2–4 Hz bin; one that
    swings 0.7 times a second, in the 0.5–1 Hz bin; a still group sits at the floor."""
    frames = np.concatenate([envelope_windows(3.0), envelope_windows(0.7)], axis=2)
    frames[..., :4] = 0.0  # group 0 still
    spectra = modulation_spectrum(frames, RATE, 4).reshape(1, 4, 5)
    np.testing.assert_allclose(spectra[0, 0], np.log10(MODULATION_FLOOR), atol=1e-6)
    assert np.argmax(spectra[0, 1]) == 2  # 2–4 Hz
    assert np.argmax(spectra[0, 2]) == 0  # 0.5–1 Hz


def test_level_and_colour_do_not_reach_the_spectrum() -> None:
    """A gain (a constant on every log energy) and an equaliser (a constant per band) change
    nothing; a deeper swing raises every bin it reaches."""
    frames = envelope_windows(5.0, bands=16)
    frames += np.random.default_rng(0).normal(0, 0.05, frames.shape)
    base = modulation_spectrum(frames, RATE, 4)
    coloured = frames + 0.7 + np.linspace(-1.0, 1.0, 16)
    np.testing.assert_allclose(modulation_spectrum(coloured, RATE, 4), base, atol=1e-4)
    assert np.all(modulation_spectrum(2 * frames, RATE, 4) > base)


def test_a_crop_and_a_window_share_one_scale() -> None:
    """A steady rhythm gives about the same spectrum over a quarter window as over a whole one
    (same frequency grid, power per unit of the taper's energy)."""
    frames = envelope_windows(6.0)
    whole = modulation_spectrum(frames, RATE, 2).reshape(2, 5)
    crop = modulation_spectrum(frames[:, :54], RATE, 2).reshape(2, 5)
    assert np.argmax(crop[0]) == np.argmax(whole[0]) == 3  # 4–8 Hz
    assert abs(crop[0, 3] - whole[0, 3]) < 0.5
