"""Synthesised ambient sound of the demo scenes, built from the events a listener would name.

Every function is pure: a seeded `numpy.random.Generator` and a rate in, float32 mono out. Each
scene is a bed (murmur, traffic rumble, hall noise) plus events placed at random times, then a
room (a decaying-noise impulse response: short and damped for a café, long for a sports hall).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.signal import butter, fftconvolve, lfilter, sosfilt

DEMO_RATE = 16000
# A formant filter's ringing dies away within a few milliseconds (its narrowest band is 120 Hz
# wide): a syllable filtered from this long before it sounds as it would in the whole stretch.
VOWEL_LEAD_S = 0.02


def _t(seconds: float, rate: int) -> np.ndarray:
    return np.arange(int(round(seconds * rate))) / rate


def band_sos(low: float, high: float, rate: int, order: int = 2) -> np.ndarray:
    return butter(order, [low, min(high, 0.45 * rate)], btype="band", fs=rate, output="sos")


Formant = tuple[np.ndarray, np.ndarray]  # a filter's (b, a)


def formant(low: float, high: float, rate: int) -> Formant:
    """A voice's formant: `band_sos`'s filter as (b, a), designed in half the time. A voice
    designs eight at random frequencies, and at this order the two agree to 1e-10."""
    b, a = butter(2, [low, high], btype="band", fs=rate, output="ba")
    return b, a


@lru_cache(maxsize=32)
def _fixed_sos(
    order: int, cutoff: float | tuple[float, float], btype: str, rate: int
) -> np.ndarray:
    """A filter at a fixed cutoff, designed once: a scene uses the same few hundreds of times,
    and designing one costs more than running it over a car's passing. Callers get it through
    `_sos`, a copy: the cached array is never handed out."""
    if isinstance(cutoff, tuple):
        return band_sos(cutoff[0], cutoff[1], rate, order)
    sos: np.ndarray = butter(order, cutoff, btype=btype, fs=rate, output="sos")
    return sos


def _sos(order: int, cutoff: float | tuple[float, float], btype: str, rate: int) -> np.ndarray:
    return _fixed_sos(order, cutoff, btype, rate).copy()


def bandpass(x: np.ndarray, low: float, high: float, rate: int, order: int = 2) -> np.ndarray:
    return sosfilt(_sos(order, (low, high), "band", rate), x)


def lowpass(x: np.ndarray, cutoff: float, rate: int, order: int = 2) -> np.ndarray:
    return sosfilt(_sos(order, cutoff, "low", rate), x)


def highpass(x: np.ndarray, cutoff: float, rate: int, order: int = 2) -> np.ndarray:
    return sosfilt(_sos(order, cutoff, "high", rate), x)


def place(track: np.ndarray, event: np.ndarray, at: int) -> None:
    """Add `event` into `track` starting at sample `at` (clipped at the end)."""
    end = min(len(track), at + len(event))
    if at < end:
        track[at:end] += event[: end - at]


def room(x: np.ndarray, rng: np.random.Generator, rate: int, rt60: float, wet: float) -> np.ndarray:
    """Reverberation: convolve with exponentially decaying noise that falls 60 dB in `rt60` s."""
    t = _t(rt60, rate)
    ir = rng.standard_normal(len(t)) * np.exp(-6.9 * t / rt60)
    ir = lowpass(ir, 5000.0, rate)
    ir /= np.sqrt(np.sum(ir**2))
    return (1 - wet) * x + wet * fftconvolve(x, ir)[: len(x)]


def voice(
    rng: np.random.Generator, seconds: float, rate: int, f0: float, loud: float
) -> np.ndarray:
    """A talking voice: a glottal pulse train with wandering pitch through the two formants of one
    of four vowels per syllable, ~4 syllables a second, with pauses between phrases.

    Each syllable is filtered on its own, from `VOWEL_LEAD_S` before it so that the formants ring
    as they would in the whole stretch: filtering the whole voice through all eight formants would
    take four times as long for the same sound."""
    t = _t(seconds, rate)
    pitch = f0 * (1 + 0.08 * np.sin(2 * np.pi * rng.uniform(0.5, 1.5) * t + rng.uniform(0, 6)))
    phase = np.cumsum(pitch / rate)
    source = (phase % 1.0 < 0.08).astype(float) + 0.02 * rng.standard_normal(len(t))
    formants = [(rng.uniform(300, 800), rng.uniform(900, 2500)) for _ in range(4)]
    vowels: dict[int, tuple[Formant, Formant]] = {}
    lead = int(VOWEL_LEAD_S * rate)
    out = np.zeros(len(t))
    syllable = int(rate / rng.uniform(3.5, 5.5))
    env = np.sin(np.pi * np.linspace(0, 1, syllable)) ** 2
    for start in range(0, len(t), syllable):
        if rng.random() < 0.25:
            continue
        k = int(rng.integers(4))
        if k not in vowels:
            f1, f2 = formants[k]
            vowels[k] = (formant(f1 * 0.8, f1 * 1.2, rate), formant(f2 * 0.85, f2 * 1.15, rate))
        (b1, a1), (b2, a2) = vowels[k]
        begin = max(0, start - lead)
        stretch = source[begin : start + syllable]
        seg = (lfilter(b1, a1, stretch) + 0.6 * lfilter(b2, a2, stretch))[start - begin :]
        out[start : start + len(seg)] = seg * env[: len(seg)]
    return loud * out / (np.max(np.abs(out)) + 1e-9)


def clink(rng: np.random.Generator, rate: int) -> np.ndarray:
    """A cup on a saucer, a spoon on china: inharmonic partials of 2–6 kHz, ringing briefly."""
    t = _t(0.25, rate)
    base = rng.uniform(2000, 3500)
    partials = sum(
        a * np.sin(2 * np.pi * base * r * t + rng.uniform(0, 6))
        for a, r in ((1.0, 1.0), (0.6, 1.59), (0.4, 2.14), (0.25, 2.87))
    )
    return rng.uniform(0.05, 0.15) * partials * np.exp(-t / rng.uniform(0.03, 0.07))


def espresso(rng: np.random.Generator, seconds: float, rate: int) -> np.ndarray:
    """The espresso machine: a steam wand's hiss (high-passed noise) over its pump's 50 Hz buzz."""
    t = _t(seconds, rate)
    hiss = highpass(rng.standard_normal(len(t)), 3000.0, rate, order=4)
    pump = sum(np.sin(2 * np.pi * 50 * k * t) / k for k in range(1, 6))
    fade = np.minimum(1, np.minimum(t, t[::-1]) / 0.3)
    return fade * (0.05 * hiss + 0.02 * pump)


def coffee_shop(rng: np.random.Generator, seconds: float, rate: int = DEMO_RATE) -> np.ndarray:
    n = int(round(seconds * rate))
    x = sum(
        voice(rng, seconds, rate, rng.uniform(95, 240), rng.uniform(0.02, 0.05)) for _ in range(6)
    )
    x = np.asarray(x, dtype=float)
    for _ in range(rng.poisson(2.5 * seconds)):
        place(x, clink(rng, rate), int(rng.integers(0, n)))
    if rng.random() < 0.8:
        length = rng.uniform(1.5, 3.5)
        place(x, espresso(rng, length, rate), int(rng.integers(0, max(1, n - int(length * rate)))))
    return room(x, rng, rate, rt60=0.4, wet=0.3).astype(np.float32)


def bounce(rng: np.random.Generator, rate: int) -> np.ndarray:
    """A basketball on a wooden floor: a low thump whose pitch drops, with a slap on top."""
    t = _t(0.2, rate)
    f = 140 * np.exp(-t / 0.05) + 70
    thump = np.sin(2 * np.pi * np.cumsum(f) / rate) * np.exp(-t / 0.04)
    slap = highpass(rng.standard_normal(len(t)), 1500.0, rate) * np.exp(-t / 0.006)
    return 0.35 * thump + 0.08 * slap


def squeak(rng: np.random.Generator, rate: int) -> np.ndarray:
    """A sneaker's squeak: a bright chirp around 1–3 kHz with its harmonics, ~0.15 s."""
    length = rng.uniform(0.08, 0.2)
    t = _t(length, rate)
    f = rng.uniform(1000, 2000) + rng.uniform(-600, 900) * t / length
    phase = 2 * np.pi * np.cumsum(f) / rate
    tone = np.sin(phase) + 0.5 * np.sin(2 * phase) + 0.3 * np.sin(3 * phase)
    return 0.12 * tone * np.sin(np.pi * t / length)


def whistle(rng: np.random.Generator, rate: int) -> np.ndarray:
    """A referee's whistle: ~3 kHz, trilled by the pea at ~30 Hz."""
    length = rng.uniform(0.4, 0.9)
    t = _t(length, rate)
    f = rng.uniform(2800, 3300) * (1 + 0.02 * np.sin(2 * np.pi * 30 * t))
    tone = np.sin(2 * np.pi * np.cumsum(f) / rate)
    return (
        0.25
        * tone
        * (0.7 + 0.3 * np.sin(2 * np.pi * 30 * t))
        * np.minimum(1, np.minimum(t, t[::-1]) / 0.02)
    )


def gym(rng: np.random.Generator, seconds: float, rate: int = DEMO_RATE) -> np.ndarray:
    n = int(round(seconds * rate))
    x = 0.004 * lowpass(rng.standard_normal(n), 400.0, rate)  # ventilation of a big hall
    for _ in range(rng.integers(1, 3)):  # players dribbling, ~2 bounces a second each
        at, period = rng.uniform(0, 0.5), rng.uniform(0.4, 0.6)
        while at < seconds:
            place(x, bounce(rng, rate) * rng.uniform(0.6, 1.0), int(at * rate))
            at += period * rng.uniform(0.9, 1.1)
    for _ in range(rng.poisson(1.5 * seconds)):
        place(x, squeak(rng, rate), int(rng.integers(0, n)))
    if rng.random() < 0.6:
        place(x, whistle(rng, rate), int(rng.integers(0, n)))
    for _ in range(rng.poisson(0.6 * seconds)):  # shouts: short loud high voices
        length = rng.uniform(0.3, 0.7)
        place(x, voice(rng, length, rate, rng.uniform(200, 320), 0.12), int(rng.integers(0, n)))
    return room(x, rng, rate, rt60=1.8, wet=0.55).astype(np.float32)


def car_pass(rng: np.random.Generator, rate: int) -> np.ndarray:
    """A car going by: engine and tyre noise swelling and fading, its tone falling as it passes."""
    length = rng.uniform(2.5, 4.5)
    t = _t(length, rate)
    swell = 1 / (1 + ((t - length / 2) / (0.25 * length)) ** 2)
    tyres = bandpass(rng.standard_normal(len(t)), 200.0, 1500.0, rate)
    f = rng.uniform(60, 110) * (1 + 0.1 * np.tanh(-(t - length / 2) * 3))
    engine = np.sign(np.sin(2 * np.pi * np.cumsum(f) / rate))
    return rng.uniform(0.04, 0.09) * swell * (tyres + 0.3 * lowpass(engine, 300.0, rate))


def horn(rng: np.random.Generator, rate: int) -> np.ndarray:
    """A car horn: two square-ish tones a third apart, ~0.4 s."""
    t = _t(rng.uniform(0.25, 0.6), rate)
    f = rng.uniform(380, 450)
    tone = np.sign(np.sin(2 * np.pi * f * t)) + np.sign(np.sin(2 * np.pi * f * 1.26 * t))
    return 0.05 * lowpass(tone, 2500.0, rate) * np.minimum(1, np.minimum(t, t[::-1]) / 0.01)


def street(rng: np.random.Generator, seconds: float, rate: int = DEMO_RATE) -> np.ndarray:
    n = int(round(seconds * rate))
    rumble = np.cumsum(rng.standard_normal(n))  # brown noise: distant traffic
    rumble = highpass(rumble, 20.0, rate)
    x = 0.02 * rumble / (np.std(rumble) + 1e-9)
    for _ in range(rng.poisson(0.5 * seconds) + 1):
        place(x, car_pass(rng, rate), int(rng.integers(-2 * rate, n)) % n)
    if rng.random() < 0.35:
        place(x, horn(rng, rate), int(rng.integers(0, n)))
    for _ in range(rng.poisson(1.0 * seconds)):  # footsteps of passers-by
        t = _t(0.05, rate)
        step = lowpass(rng.standard_normal(len(t)), 800.0, rate) * np.exp(-t / 0.01)
        place(x, 0.03 * step, int(rng.integers(0, n)))
    return room(x, rng, rate, rt60=0.3, wet=0.1).astype(np.float32)


SCENE_SOUNDS = {"coffee": coffee_shop, "gym": gym, "street": street}
