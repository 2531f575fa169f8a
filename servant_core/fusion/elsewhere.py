"""How sure the senses together are that the wearer is in a taught place and not somewhere else.

An open sense (`open_proba`) gives each taught place P(there and not elsewhere), the rest being
elsewhere; a closed sense gives shares among the taught places. Naive Bayes, senses independent:
    P(s | senses) ∝ Π_open p_k(s) · Π_closed K·q_k(s);   P(elsewhere | senses) ∝ Π_open p_k(else)
K·q_k(s) is a closed sense's likelihood ratio of s against the average taught place (1: no
change). With no open sense, the least sure sense's share.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Collection, Mapping, Sequence
from typing import Any

from servant_core.events import Decision
from servant_core.fusion.sequential import scene_line
from servant_core.recognisers.base import PERCENT, knows_elsewhere

# A place is decided when it is likelier than not that the wearer is there and not elsewhere.
OPEN_DECIDE_AT = 0.5

# The unit of a closed sense's figure beside a sound that knows somewhere else (`likelier`)
LIKELIER_UNIT = "× average"


def likelier(scene: str, shares: Mapping[str, float]) -> float:
    """How many times likelier a closed sense's shares among the taught places make `scene`
    than the average taught place (K·q above): 1.0 says nothing either way, as a coin toss
    between two places does, which as a share reads "50 %" (pure)."""
    return len(shares) * shares.get(scene, 0.0)


def beside_open_sound(acoustic: Any, recogniser: Any) -> bool:
    """Whether a sense's recogniser knows only the taught places while the sound's (`acoustic`,
    None: no sound) knows somewhere else: its shares are then shown as `likelier`."""
    return acoustic is not None and knows_elsewhere(acoustic) and not knows_elsewhere(recogniser)


def shown(
    scene: str | None,
    confidence: float,
    unit: str | None,
    shares: Mapping[str, float],
    closed_beside_open: bool,
) -> tuple[float, str | None]:
    """The figure and unit a sense's prediction is shown with (the log, the Scene pane,
    `servant run --headless`, `servant predict`). A closed sense's share among the taught
    places (pictures, motion, ambient) beside a sound that knows somewhere else
    (`closed_beside_open`) is shown as how much likelier it makes its place than the average
    taught place (`likelier`, what it weighs in the decision): as a share, two places taught
    made every picture "50 %", which reads as a confidence the decision never had (pure)."""
    if scene is None or unit != PERCENT or not closed_beside_open:
        return confidence, unit
    return likelier(scene, shares), LIKELIER_UNIT


def elsewhere_mass(scores: Mapping[str, float]) -> float:
    """What an open sense's probabilities leave for somewhere else (pure)."""
    return max(0.0, 1.0 - sum(scores.values()))


def place_probability(
    scene: str,
    scores: Mapping[str, Mapping[str, float]],
    senses: Sequence[str],
    open_senses: Collection[str],
) -> float:
    """The probability (0–1) that the wearer is in `scene` and not somewhere else, given the
    latest probabilities of `senses` (`scores[sense][place]`); `open_senses` are those whose
    probabilities leave room for somewhere else (pure)."""
    present = [s for s in senses if scores.get(s)]
    if not any(s in open_senses for s in present):
        return min((scores.get(s, {}).get(scene, 0.0) for s in senses), default=0.0)
    places = set().union(*(scores[s] for s in present))
    weight = dict.fromkeys(places, 1.0)
    weight_elsewhere = 1.0
    for sense in present:
        probabilities = scores[sense]
        if sense in open_senses:
            for place in places:
                weight[place] *= probabilities.get(place, 0.0)
            weight_elsewhere *= elsewhere_mass(probabilities)
        else:
            n = len(probabilities)
            for place in places:
                # a place this sense was never taught (labelled from its sound alone: no picture
                # of it) is one it has no evidence about, for or against
                weight[place] *= n * probabilities[place] if place in probabilities else 1.0
    total = sum(weight.values()) + weight_elsewhere
    return weight.get(scene, 0.0) / total if total > 0 else 0.0


def open_decision(
    decision: Decision,
    scores: Mapping[str, Mapping[str, float]],
    senses: Sequence[str],
    open_senses: Collection[str],
) -> Decision:
    """A decision of a place, its figure made the probability of that place and not somewhere
    else from `senses` (`place_probability`); one likelier somewhere else (under
    `OPEN_DECIDE_AT`) is no decision, as the parallel policy decides: what the live engine and
    `servant predict` make of a decision a policy that knows only the taught places reached (a
    learned net leaning on pictures, the paper's rule) (pure)."""
    sure = place_probability(str(decision.scene), scores, senses, open_senses)
    if sure < OPEN_DECIDE_AT:
        return dataclasses.replace(
            decision, scene=None, line=scene_line(None), confidence=0.0, not_elsewhere=False
        )
    return dataclasses.replace(decision, confidence=100.0 * sure, not_elsewhere=True)


def steady_open(
    window: Mapping[str, float],
    previous: Mapping[str, float],
    far: bool,
    named_before: str | None = None,
    sure_alone: float | None = None,
    far_alone: bool = False,
) -> tuple[str | None, dict[str, float]]:
    """What a sense that knows somewhere else says of a window, held steady (pure).

    Arriving: each place gets the smaller of its probability in this window and `previous`. Staying:
    `named_before` stays while it is this window's likeliest and the two give it half or more on
    average (held at that average). Arriving sure: else this window's likeliest place when it has
    `sure_alone` or more and is not `far_alone` (None: never). Returns (the place, or None where
    somewhere else keeps half or more or the window is `far`; the held probabilities).
    """
    scores = {s: min(window.get(s, 0.0), previous.get(s, 0.0)) for s in window}
    if far or not scores:
        return None, scores
    if named_before in window and max(window, key=lambda s: window[s]) == named_before:
        scores[named_before] = (window[named_before] + previous.get(named_before, 0.0)) / 2
    if elsewhere_mass(scores) < 0.5:
        return max(scores, key=lambda s: scores[s]), scores
    likeliest = max(window, key=lambda s: window[s])
    if sure_alone is not None and not far_alone and window[likeliest] >= sure_alone:
        return likeliest, dict(window)
    return None, scores
