import cv2
import numpy as np
import pytest

from servant_core.features.palette import dominant_colours
from servant_core.features.paper_fft import PCM_SCALE, paper_fft_vector, paper_fft_vectors
from servant_core.recognisers.paper import paper_confidence
from tests.conftest import tone


def test_pure_tone_lands_in_its_bin():
    rate, seconds, freq = 8000, 1.0, 1234.0
    vector = paper_fft_vector(tone(freq, seconds, rate), rate)
    half = len(vector) // 2
    freqs, amps = vector[:half], vector[half:]
    assert half == int(rate * seconds) // 2 + 1
    assert freqs[0] == 0 and freqs[-1] == rate / 2
    assert freqs[np.argmax(amps)] == pytest.approx(freq)
    # a full-scale-0.5 sine of N samples has |X| = A*N/2 at its bin, in PCM units
    assert np.max(amps) == pytest.approx(0.5 * PCM_SCALE * rate * seconds / 2, rel=1e-3)


def test_batch_equals_single():
    rng = np.random.default_rng(1)
    windows = rng.normal(size=(3, 800)).astype(np.float32)
    batch = paper_fft_vectors(windows, 8000)
    for row, window in zip(batch, windows, strict=True):
        assert np.allclose(row, paper_fft_vector(window, 8000), rtol=1e-5)


def test_two_colour_picture_gives_those_colours_and_shares():
    image = np.zeros((480, 640, 3), np.uint8)
    image[:, :160] = (0, 0, 255)  # BGR red, a quarter
    image[:, 160:] = (255, 128, 0)  # BGR blue-ish, three quarters
    colours, shares = dominant_colours(image, n_colours=2)
    assert colours.tolist() == [[0, 128, 255], [255, 0, 0]]  # RGB, largest share first
    assert shares == pytest.approx([0.75, 0.25], abs=0.01)


def test_dominant_colours_of_a_noisy_picture_are_stable_and_ordered():
    rng = np.random.default_rng(0)
    image = np.full((120, 160, 3), (40, 200, 90), np.uint8)
    image[:30] = (220, 30, 30)
    noisy = np.clip(image + rng.normal(0, 4, image.shape), 0, 255).astype(np.uint8)
    colours, shares = dominant_colours(cv2.cvtColor(noisy, cv2.COLOR_RGB2BGR), n_colours=2)
    assert np.allclose(colours[0], (40, 200, 90), atol=4)
    assert np.allclose(colours[1], (220, 30, 30), atol=4)
    assert shares.sum() == pytest.approx(1.0)
    assert shares[0] == pytest.approx(0.75, abs=0.02)


def test_paper_confidence_equations():
    # eq. 1: A=(0, 0), B=(30000, 40000): ||A-B|| = 50000 -> 100 - 5 = 95
    assert paper_confidence(np.linalg.norm([30000, 40000]), 10000) == pytest.approx(95.0)
    # eq. 2: colours (10, 20, 30) vs (13, 24, 30): distance 5 -> 95
    assert paper_confidence(np.linalg.norm([3, 4, 0]), 1) == pytest.approx(95.0)
    # far points go below zero, as the paper's formula does
    assert paper_confidence(300.0, 1) == pytest.approx(-200.0)
