"""The user's settings: devices, the arm's joints and the decision windows, kept in one JSON file.

`load_settings()` reads `config_dir()/settings.json`; a missing file gives the defaults, a broken
one is refused in one line naming it and is never overwritten. `save_settings()` writes atomically.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from servant_core.errors import ServantError
from servant_core.storage import atomic_write_json, config_dir

FORMAT = "servant-settings"
VERSION = 1
PROTOCOLS = ("maestro", "ssc32", "firmata")


@dataclass(frozen=True)
class Joint:
    """One servo of the arm: its controller channel, its angle limits and calibration, its speed.

    The angle limits are also the calibration points: `min_angle` is sent as `min_pulse_us` and
    `max_angle` as `max_pulse_us`, linearly between. No command ever leaves [min_angle, max_angle].
    """

    name: str
    channel: int
    min_angle: float
    max_angle: float
    min_pulse_us: float
    max_pulse_us: float
    max_speed_deg_s: float
    home_angle: float

    def problems(self) -> list[str]:
        """What is wrong with this joint, if anything (empty when it is safe to drive)."""
        lines = []
        numbers = (self.min_angle, self.max_angle, self.min_pulse_us, self.max_pulse_us)
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in numbers):
            return [f"joint {self.name!r}: angles and pulses must be finite numbers"]
        if not self.name:
            lines.append("a joint has an empty name")
        if not isinstance(self.channel, int) or not 0 <= self.channel <= 127:
            lines.append(f"joint {self.name!r}: channel must be an integer 0..127")
        if not self.min_angle < self.max_angle:
            lines.append(f"joint {self.name!r}: min_angle must be below max_angle")
        if not 400 <= self.min_pulse_us < self.max_pulse_us <= 2600:
            lines.append(
                f"joint {self.name!r}: pulses must satisfy "
                "400 <= min_pulse_us < max_pulse_us <= 2600"
            )
        speed = self.max_speed_deg_s
        if not (isinstance(speed, int | float) and math.isfinite(speed) and speed > 0):
            lines.append(f"joint {self.name!r}: max_speed_deg_s must be a positive number")
        home = self.home_angle
        if not (isinstance(home, int | float) and self.min_angle <= home <= self.max_angle):
            lines.append(f"joint {self.name!r}: home_angle must lie within min_angle..max_angle")
        return lines


def default_joints() -> list[Joint]:
    """A three-joint wearable arm with conservative limits and slow speeds.

    Channels 3-5 exist on every supported controller (a Micro Maestro has 0-5) and are free
    digital pins on an Arduino, whose pins 0 and 1 carry the serial link itself. 1000-2000 us is
    the range every hobby servo accepts (90 degrees per 500 us), so the limits stay well inside it.
    """
    return [
        Joint("shoulder", 3, 0.0, 90.0, 1000.0, 1500.0, 30.0, 0.0),
        Joint("elbow", 4, 0.0, 135.0, 1000.0, 1750.0, 45.0, 90.0),
        Joint("gripper", 5, 0.0, 90.0, 1000.0, 1500.0, 60.0, 0.0),
    ]


@dataclass
class Settings:
    audio_device: str | int | None = None  # a sounddevice name or index; None: the default input
    camera: str | int | None = None  # a camera index, a video file or an image pattern
    serial_port: str | None = None
    protocol: str = "maestro"
    joints: list[Joint] = field(default_factory=default_joints)
    acoustic_window_s: float = 30.0  # the paper: a visual prediction must follow within 30 s
    confirm_window_s: float = 20.0  # the paper: pictures confirm within 20 s
    pictures_needed: int = 3
    picture_interval_s: float = 2.0
    confidence_threshold: float = 50.0  # percent; the arm does not act on a less sure decision

    def joint(self, name: str) -> Joint:
        for joint in self.joints:
            if joint.name == name:
                return joint
        names = ", ".join(j.name for j in self.joints)
        raise ServantError(f"no joint named {name!r}; the arm's joints are: {names}")

    def problems(self) -> list[str]:
        lines = [line for joint in self.joints for line in joint.problems()]
        if self.protocol not in PROTOCOLS:
            lines.append(
                f"protocol {self.protocol!r} is unknown; use one of {', '.join(PROTOCOLS)}"
            )
        names = [j.name for j in self.joints]
        if len(set(names)) != len(names):
            lines.append("two joints share a name")
        channels = [j.channel for j in self.joints]
        if len(set(channels)) != len(channels):
            lines.append("two joints share a channel")
        for name in ("acoustic_window_s", "confirm_window_s", "picture_interval_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and value > 0):
                lines.append(f"{name} must be a positive number of seconds")
        if not (isinstance(self.pictures_needed, int) and self.pictures_needed >= 1):
            lines.append("pictures_needed must be a positive integer")
        if not (
            isinstance(self.confidence_threshold, int | float)
            and 0 <= self.confidence_threshold <= 100
        ):
            lines.append("confidence_threshold must be a percentage, 0..100")
        return lines

    def to_json(self) -> dict[str, Any]:
        return {"format": FORMAT, "version": VERSION, **asdict(self)}


def default_settings_path() -> Path:
    return config_dir() / "settings.json"


def load_settings(path: str | Path | None = None) -> Settings:
    """The settings in `path` (default `config_dir()/settings.json`); defaults if missing."""
    path = Path(path) if path is not None else default_settings_path()
    if not path.exists():
        return Settings()
    fix = "fix or delete it to get the defaults"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ServantError(f"{path}: not a readable settings file ({exc}); {fix}") from exc
    if not isinstance(data, dict) or data.get("format", FORMAT) != FORMAT:
        raise ServantError(f"{path}: not a Servant settings file; {fix}")
    version = data.pop("version", VERSION)
    data.pop("format", None)
    if not isinstance(version, int) or version > VERSION:
        raise ServantError(
            f"{path}: settings version {version!r} is newer than this Servant reads; "
            "upgrade Servant"
        )
    known = {f.name for f in fields(Settings)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ServantError(f"{path}: unknown setting(s) {', '.join(unknown)}; {fix}")
    try:
        if "joints" in data:
            data["joints"] = [Joint(**joint) for joint in data["joints"]]
        settings = Settings(**data)
    except TypeError as exc:
        raise ServantError(f"{path}: a joint is malformed ({exc}); {fix}") from exc
    problems = settings.problems()
    if problems:
        raise ServantError(f"{path}: {problems[0]}; {fix}")
    return settings


def save_settings(settings: Settings, path: str | Path | None = None) -> Path:
    """Write the settings atomically; settings that could drive the arm unsafely are refused."""
    path = Path(path) if path is not None else default_settings_path()
    problems = settings.problems()
    if problems:
        raise ServantError(f"{path}: not saved: {problems[0]}")
    return atomic_write_json(path, settings.to_json())
