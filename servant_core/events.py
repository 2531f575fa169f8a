"""Typed events the engine emits to its subscribers (the TUI, the headless CLI, tests).

Every event carries `t`, the engine clock's time in seconds when it happened. Events are frozen
dataclasses holding plain values and numpy arrays, so they can cross threads safely.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class SpectrumFrame:
    """A short spectrum of the latest audio, for the live spectrum pane (~30 per second)."""

    t: float
    freqs: np.ndarray  # Hz, ascending
    magnitude_db: np.ndarray  # dB re full scale, same length as freqs


@dataclass(frozen=True)
class Palette:
    """The dominant colours of one frame, ordered by share (largest first)."""

    t: float
    colours: np.ndarray  # (k, 3) uint8, RGB
    shares: np.ndarray  # (k,) float, sums to 1
    matched_scene: str | None = None
    matched_colours: np.ndarray | None = None  # the training palette it matched, (k, 3) RGB


@dataclass(frozen=True)
class AcousticPrediction:
    t: float
    scene: str | None  # None: unknown place (open set)
    confidence: float  # the paper's eq. 1 in paper mode, else a probability in percent
    scores: dict[str, float] = field(default_factory=dict)  # per scene, sums to 1 when calibrated
    # The recogniser's `confidence_unit`: "%", or "eq. 1" in paper mode; None: not said.
    confidence_unit: str | None = None
    silent: bool = False  # the window was silence: no recogniser was asked about it


@dataclass(frozen=True)
class VisualPrediction:
    t: float
    scene: str | None
    confidence: float  # the paper's eq. 2 in paper mode, else a probability in percent
    scores: dict[str, float] = field(default_factory=dict)
    # The recogniser's `confidence_unit`: "%", or "eq. 2" in paper mode; None: not said.
    confidence_unit: str | None = None


@dataclass(frozen=True)
class SensePrediction:
    """A window's judgement by a sense other than sound and pictures (motion, ambient)."""

    t: float
    sense: str  # its name in `servant_core.senses.SENSES`
    scene: str | None  # None: unknown place
    confidence: float  # a probability in percent
    scores: dict[str, float] = field(default_factory=dict)
    confidence_unit: str | None = None


@dataclass(frozen=True)
class SensorFrame:
    """The latest readings of a sample sense, for a live trace (a few per second)."""

    t: float
    sense: str
    channels: tuple[str, ...]  # the columns of `rows`
    rows: np.ndarray  # (n, channels) float32, oldest first
    rate: int  # rows per second


@dataclass(frozen=True)
class FusionState:
    """Where the fusion policy stands: which window is open, how long is left."""

    t: float
    phase: str  # "listening" | "looking" | "confirming"
    scene: str | None  # the acoustic scene being confirmed, if any
    seconds_left: float | None
    pictures_taken: int


@dataclass(frozen=True)
class Decision:
    """A fused decision: the paper's terminal line and the averaged confidence."""

    t: float
    scene: str | None  # None: "No scene detected"
    confidence: float  # average of the two senses' confidences (see `not_elsewhere`); 0.0: none
    line: str  # "CoffeeScene detected" / "No scene detected"
    acoustic_confidence: float = 0.0
    visual_confidence: float = 0.0
    # "%" when both senses' confidences are percentages; None when they are not (the paper's
    # eq. 1 and eq. 2 averaged) or not said.
    confidence_unit: str | None = None
    # The senses the decision leaned on, most first (the learned fusion says; the rule
    # policies leave it empty).
    leaned_on: tuple[str, ...] = ()
    # True when `confidence` is the probability of this place and not somewhere else, from the
    # senses together (`fusion.elsewhere`), rather than an average of their confidences.
    not_elsewhere: bool = False


@dataclass(frozen=True)
class UnknownScene:
    """The engine heard or saw a place it does not know, and asks the user to label it."""

    t: float
    sense: str  # "audio", "image", or a sample sense ("motion", "ambient")
    nearest_scene: str | None
    window_id: str  # a handle the engine accepts back with the user's label


@dataclass(frozen=True)
class DeviceStatus:
    t: float
    device: str  # "microphone" | "camera" | "servo"
    ok: bool
    message: str


@dataclass(frozen=True)
class ArmState:
    t: float
    connected: bool
    armed: bool
    protocol: str | None
    port: str | None
    angles: dict[str, float]  # current angle per joint, degrees
    target: dict[str, float] | None = None  # the pose about to be sent
    pose_of: str | None = None  # the scene whose pose the arm has just taken (after a move)


@dataclass(frozen=True)
class Notice:
    """Something the user should know that is not a fault: what to do next, why the arm stays."""

    t: float
    message: str  # one line


@dataclass(frozen=True)
class ErrorEvent:
    t: float
    message: str  # one line: what is wrong and what to do


Event = (
    SpectrumFrame
    | Palette
    | AcousticPrediction
    | VisualPrediction
    | SensePrediction
    | SensorFrame
    | FusionState
    | Decision
    | UnknownScene
    | DeviceStatus
    | ArmState
    | Notice
    | ErrorEvent
)
