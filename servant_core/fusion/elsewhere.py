"""How sure the senses together are that the wearer is in a taught place and not somewhere else.

A sense whose recogniser knows somewhere else (it learned a background: `open_proba`) gives each
taught place the probability that the wearer is there *and not elsewhere*; the rest of its
probability is "elsewhere". A sense that knows only the taught places (the pictures, motion,
ambient: nothing of somewhere else was ever shown to them) gives shares among the taught places;
it can say which taught place a moment looks like, not whether it is one. Together, as a naive
Bayes product with the senses independent given the place:

    P(s | senses) ∝ Π_open p_k(s) · Π_closed K·q_k(s)      for each taught place s
    P(elsewhere | senses) ∝ Π_open p_k(elsewhere) · 1

where K·q_k(s) is a closed sense's likelihood ratio of s against the average taught place. A
closed sense that cannot tell the places apart (two places, a picture at 50 %) is K·q = 1: it
changes nothing, rather than making every picture "50 % sure". With no open sense at all the old
rule stands: the least sure sense's share.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence


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
                weight[place] *= n * probabilities.get(place, 0.0)
    total = sum(weight.values()) + weight_elsewhere
    return weight.get(scene, 0.0) / total if total > 0 else 0.0


def steady_open(
    window: Mapping[str, float], previous: Mapping[str, float], far: bool
) -> tuple[str | None, dict[str, float]]:
    """What a sense that knows somewhere else says of a window, held steady: each taught place
    gets the smaller of its probability in this window and in the one before, so a place is
    named only when two windows in a row say so: neither one odd window nor the last place,
    lingering in the first window of the next, can name a place alone (pure). Returns (the
    place, or None where somewhere else keeps half the probability or more, or the window is
    `far` from every taught place; the held probabilities)."""
    scores = {s: min(window.get(s, 0.0), previous.get(s, 0.0)) for s in window}
    if far or not scores or elsewhere_mass(scores) >= 0.5:
        return None, scores
    return max(scores, key=lambda s: scores[s]), scores
