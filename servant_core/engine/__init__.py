"""The engine, split by role: `core` (the `Engine`: its life cycle, coordinating the parts),
`bus` (events), `sense_devices` and `loop` (the devices side of the sense loop), `judging`
(windows and pictures to predictions, decisions and the arm), `unknown_places` ("What is this
place?" and its label), `models` and `learning` (the recognisers; retrain, fold-in, saving),
`arm` (the link and the poses; `arm_commands`, the engine's), `parts` (the parts made and wired
together), `fusion_settings` (the user's fusion windows) and `factories` (the demo's and the
live engine). Front ends import from here.
"""

from servant_core.capture.source import ManualClock, MonotonicClock
from servant_core.engine.arm import NO_POSE, Pose, PoseFor
from servant_core.engine.bus import Subscriber
from servant_core.engine.core import NO_MODEL, Engine
from servant_core.engine.factories import (
    LiveSettings,
    build_demo_engine,
    build_live_engine,
    pose_for_taught,
    steady,
)
from servant_core.engine.fusion_settings import fusion_config
from servant_core.engine.judging import _predict, decision_unit
from servant_core.engine.learning import UNKNOWN_KEPT
from servant_core.engine.loop import RING_SECONDS, SPECTRUM_FPS, SPECTRUM_SIZE, spectrum_db
from servant_core.recognisers import FRESH_METHODS

__all__ = [
    "FRESH_METHODS",
    "NO_MODEL",
    "NO_POSE",
    "RING_SECONDS",
    "SPECTRUM_FPS",
    "SPECTRUM_SIZE",
    "UNKNOWN_KEPT",
    "Engine",
    "LiveSettings",
    "ManualClock",
    "MonotonicClock",
    "Pose",
    "PoseFor",
    "Subscriber",
    "_predict",
    "build_demo_engine",
    "build_live_engine",
    "decision_unit",
    "fusion_config",
    "pose_for_taught",
    "spectrum_db",
    "steady",
]
