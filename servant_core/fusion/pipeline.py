"""Servant's one decision pipeline: each sense's opinion and its time in, decisions out.

The live engine, `servant predict`, `servant eval fusion` and (through the engine)
`bench/wearer_day.py` all decide through a `DecisionPipeline`; none of them decides on its own.
It is pure: no threads, no devices, the time passed in by the caller, who also serialises the
calls (the engine holds its lock).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Sequence
from typing import Any

from servant_core.events import Decision, FusionState
from servant_core.fusion.elsewhere import open_decision, steady_open
from servant_core.fusion.sequential import FusionConfig, scene_line
from servant_core.fusion.smoothing import SceneSmoother
from servant_core.recognisers.base import UNKNOWN
from servant_core.senses import SENSES

Said = tuple[str, float, dict[str, float] | None]
"""One sense's opinion: its scene (or UNKNOWN), its confidence, its scores (None: not given)."""

ROLE_OF = {sense: SENSES[sense].role for sense in ("audio", "image")}  # what every policy hears

ARRIVE_SURE = 0.9
"""A sound window alone names a place it gives this probability or more (`steady_open`'s
`sure_alone`); two windows in a row name any place likelier than not. Chosen among 0.7, 0.8 and
0.9 on the walk over half 0 of the sources, walked on half 1 (docs/research.md, issue 39)."""


class DecisionPipeline:
    """From opinions to decision events, in four steps a caller drives in this order:

    - `hear`: a sound window's opinion held steady (`steady_open` or the `smoother`);
    - `note`: a sense's latest scores, and whether they leave room for somewhere else;
    - `tell`: the opinion to the fusion policy, which may return a `Decision`;
    - `settle`: a policy's decision as the wearer and the arm take it (`open_decision`).

    `tick`, `wants_picture` and `state` pass the clock to the policy."""

    def __init__(
        self,
        policy: Any,
        smoother: SceneSmoother | None = None,
        roles: Iterable[str] = ROLE_OF.values(),
        arrive_sure: float | None = ARRIVE_SURE,
    ) -> None:
        self.policy = policy
        self.arrive_sure = arrive_sure
        self.smoother = smoother
        self.scores: dict[str, dict[str, float]] = {role: {} for role in roles}
        self.open_roles: set[str] = set()  # roles whose probabilities know somewhere else
        self.forget()

    def forget(self) -> None:
        """A new sound model: what the old one believed about past windows means nothing."""
        if self.smoother is not None:
            self.smoother.reset()
        self._previous: dict[str, float] | None = None
        self._previous_far = False  # the last window was far from every taught place
        self._named_before: str | None = None  # the place the last window named, if any

    def hear(
        self, scene: str, confidence: float, scores: dict[str, float], unit: str | None, open_: bool
    ) -> tuple[str, float, dict[str, float]]:
        """A sound window's (scene or UNKNOWN, confidence, scores), held steady.

        Open (`open_`): unknown though its probabilities name a place is far from every place
        taught; held steady as the probabilities are, two far windows in a row, not one odd one,
        or one window alone where it is sure (`steady_open`, `arrive_sure`). Shares in percent
        go through the smoother when there is one."""
        if open_:
            far = scene == UNKNOWN and sum(scores.values()) > 0.5
            previous, self._previous = self._previous, scores
            far_before, self._previous_far = self._previous_far, far
            named, held = steady_open(
                scores,
                previous or {},
                far and far_before,
                self._named_before,
                sure_alone=self.arrive_sure,
                far_alone=far,
            )
            self._named_before = named
            return (UNKNOWN, 0.0, held) if named is None else (named, 100.0 * held[named], held)
        if self.smoother is not None and unit == "%":
            belief = self.smoother.update({UNKNOWN: 1.0} if scene == UNKNOWN else scores)
            best = max(belief, key=lambda s: belief[s])
            return best, 100.0 * belief[best], {s: p for s, p in belief.items() if s != UNKNOWN}
        return scene, confidence, scores

    def note(self, role: str, scores: dict[str, float], open_: bool) -> None:
        """A role's latest scores; `open_`: they leave room for somewhere else."""
        self.scores[role] = scores
        if open_:
            self.open_roles.add(role)
        else:
            self.open_roles.discard(role)

    def latest(self) -> dict[str, dict[str, float]]:
        """A copy of every role's latest scores."""
        return {role: dict(scores) for role, scores in self.scores.items()}

    def tell(
        self,
        sense: str,
        scene: str | None,
        confidence: float,
        t: float,
        scores: dict[str, float] | None,
    ) -> list[Any]:
        """A sense's judgement (None or UNKNOWN: no place) to the policy: a policy that hears
        every sense (`hears_every_sense`, the learned one) hears them all with their
        probabilities; the rule policies hear sound and pictures only, and one that weighs
        scores (`weighs_scores`, the parallel one) takes the pictures as evidence, not votes,
        once the sound knows somewhere else."""
        scene = None if scene == UNKNOWN else scene
        policy = self.policy
        if policy.hears_every_sense:
            return list(policy.on_sense(sense, scene, confidence, t, scores))
        if sense not in ROLE_OF:
            return []
        judge = policy.on_acoustic if sense == "audio" else policy.on_visual
        open_sound = sense == "image" or "acoustic" in self.open_roles
        if policy.weighs_scores and scores is not None and open_sound:
            return list(judge(scene, confidence, t, scores=scores))
        return list(judge(scene, confidence, t))

    def tick(self, t: float) -> list[Any]:
        return list(self.policy.tick(t))

    def wants_picture(self, t: float) -> bool:
        return bool(self.policy.wants_picture(t))

    def state(self, t: float) -> FusionState:
        return self.policy.state(t)  # type: ignore[no-any-return]

    def settle(self, decision: Decision) -> tuple[Decision, tuple[str, ...]]:
        """A policy's decision of a place as the wearer and the arm take it, and the roles it
        rests on (those of the senses it leaned on, `SENSES`). A sense that knows
        somewhere else and has spoken has its say, leaned on or not: pictures alone (a learned
        net's choice) cannot tell a taught place from elsewhere."""
        roles = tuple(SENSES[s].role for s in decision.leaned_on if s in SENSES)
        roles = roles or tuple(ROLE_OF.values())
        heard_open = sorted(r for r in self.open_roles if self.scores.get(r))
        if heard_open and not decision.not_elsewhere and decision.scene is not None:
            roles = tuple(dict.fromkeys([*roles, *heard_open]))
            decision = open_decision(decision, self.latest(), roles, self.open_roles)
        return decision, roles

    def encounter(
        self,
        config: FusionConfig,
        acoustic: Said | None,
        visual: Sequence[Said],
        open_roles: Collection[str] = (),
    ) -> Decision:
        """One scene encounter in simulated time, settled: the acoustic opinion at t=0 (None: no
        sound), then pictures as the policy asks for them (cycling through `visual`; none if
        empty), until a decision. A policy that never opened a window decides nothing.
        `open_roles`: the roles whose scores leave room for somewhere else."""
        t = 0.0
        step = config.picture_interval_s / 4
        self.open_roles = set(open_roles)
        events = self._said("audio", acoustic, t) if acoustic is not None else []
        shown = 0
        horizon = config.acoustic_window_s + config.picture_interval_s + 5 * step
        while t <= horizon:
            for event in events:
                if isinstance(event, Decision):
                    return self.settle(event)[0] if event.scene else event
            t = round(t + step, 9)
            events = self.tick(t)
            if not events and visual and self.wants_picture(t):
                events = self._said("image", visual[shown % len(visual)], t)
                shown += 1
        if self.state(t).phase == "listening":
            return Decision(t, None, 0.0, scene_line(None))
        raise RuntimeError(
            f"fusion policy {type(self.policy).__name__} made no decision within its window"
        )

    def _said(self, sense: str, said: Said, t: float) -> list[Any]:
        scene, confidence, scores = said
        if scores is not None:
            role = ROLE_OF[sense]
            self.note(role, scores, role in self.open_roles)
        return self.tell(sense, scene, confidence, t, scores)
