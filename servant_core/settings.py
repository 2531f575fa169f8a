"""The user's settings: devices, the arm's joints and the decision windows, kept in one JSON file.

`load_settings()` reads `config_dir()/settings.json`; a missing file gives the defaults, a broken
one is refused in one line naming it and is never overwritten. `save_settings()` writes atomically.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

from servant_core.errors import ServantError
from servant_core.json_objects import unique_keys
from servant_core.numbers import is_finite_number, json_loads
from servant_core.storage import atomic_write_json, config_dir, no_file_yet, read_bounded_bytes

FORMAT = "servant-settings"
VERSION = 1
PROTOCOLS = ("maestro", "ssc32", "firmata")
MIN_PULSE_US, MAX_PULSE_US = 400, 2600  # beyond what any hobby servo takes
MAX_WINDOW_S = 600.0  # the paper's windows are 30 s and 20 s; ten minutes is far beyond any use
# and a tenth of a second is far below any (a picture interval of 5e-324 s passed as "above 0")
MIN_WINDOW_S = 0.1
MAX_PICTURES = 1000
# A speed above 0 but tiny (5e-324 degrees a second) made `servo move` wait for ever: the
# slowest joint worth driving turns its quarter circle in 90 s.
MIN_SPEED_DEG_S = 1.0
# The fastest hobby servos turn 60 degrees in 0.05 s; a speed of 1e305 overflowed the
# controller's speed setting.
MAX_SPEED_DEG_S = 1500.0
# A servo turns a few hundred degrees at most (a sail winch's multi-turn servos aside, which no
# arm joint is); limits beyond it (1e308 passed as finite) made moves that never end.
MAX_ABS_ANGLE = 360.0
MIN_ANGLE_SPAN = 1.0  # narrower, the speed in pulse widths a second overflowed
# A calibration narrower than this many microseconds maps a pulse read back from the controller
# to an absurd angle; every hobby servo spans hundreds.
MIN_PULSE_SPAN_US = 50.0
MAX_FILE_BYTES = 1 << 20  # a settings file is a few KiB; more is not one


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
        """What is wrong with this joint, if anything (empty when it is safe to drive).

        The first line names the fault itself, not what follows from it: with min_angle above
        max_angle no home angle can lie between them, so only the limits are blamed.
        """
        if not isinstance(self.name, str) or not self.name:
            return [f"a joint's name must be a non-empty text, not {self.name!r}"]
        lines = []
        if not _is_integer(self.channel) or not 0 <= self.channel <= 127:
            lines.append(f"joint {self.name!r}: channel must be an integer 0..127")
        numbers = ("min_angle", "max_angle", "min_pulse_us", "max_pulse_us")
        not_numbers = [n for n in numbers if not _is_number(getattr(self, n))]
        if not_numbers:
            return [*lines, f"joint {self.name!r}: {', '.join(not_numbers)} must be finite numbers"]
        if not self.min_angle < self.max_angle:
            lines.append(f"joint {self.name!r}: min_angle must be below max_angle")
        elif not (
            -MAX_ABS_ANGLE <= self.min_angle
            and self.min_angle + MIN_ANGLE_SPAN <= self.max_angle <= MAX_ABS_ANGLE
        ):
            lines.append(
                f"joint {self.name!r}: min_angle and max_angle must lie within "
                f"{-MAX_ABS_ANGLE:g}..{MAX_ABS_ANGLE:g} degrees (a servo's own range), "
                f"at least {MIN_ANGLE_SPAN:g} degree apart"
            )
        if not (
            MIN_PULSE_US <= self.min_pulse_us
            and self.min_pulse_us + MIN_PULSE_SPAN_US <= self.max_pulse_us <= MAX_PULSE_US
        ):
            lines.append(
                f"joint {self.name!r}: pulses must satisfy {MIN_PULSE_US} <= min_pulse_us and "
                f"min_pulse_us + {MIN_PULSE_SPAN_US:g} <= max_pulse_us <= {MAX_PULSE_US}"
            )
        if not (
            _is_number(self.max_speed_deg_s)
            and MIN_SPEED_DEG_S <= self.max_speed_deg_s <= MAX_SPEED_DEG_S
        ):
            lines.append(
                f"joint {self.name!r}: max_speed_deg_s must be a number from "
                f"{MIN_SPEED_DEG_S:g} to {MAX_SPEED_DEG_S:g} (degrees a second)"
            )
        home = self.home_angle
        if self.min_angle < self.max_angle and not (
            _is_number(home) and self.min_angle <= home <= self.max_angle
        ):
            lines.append(f"joint {self.name!r}: home_angle must lie within min_angle..max_angle")
        return lines


def _is_number(value: object) -> bool:
    """A finite int or float; True and False are not numbers here (JSON's `true` is no angle)."""
    return is_finite_number(value)


def _is_integer(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


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
    # the motion and ambient sensor board's serial port, or a folder of their logs; None: none
    sensor_port: str | None = None
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
        """What is wrong with these settings, the most basic first (empty when they are sound)."""
        if not isinstance(self.joints, list) or not self.joints:
            return ["the arm needs at least one joint in `joints`"]
        if not all(isinstance(j, Joint) for j in self.joints):
            return ["every joint must be an object with the joint's fields"]
        lines = [line for joint in self.joints for line in joint.problems()]
        if not lines:  # names and channels are known to be texts and integers now
            names = [j.name for j in self.joints]
            if len(set(names)) != len(names):
                lines.append("two joints share a name")
            channels = [j.channel for j in self.joints]
            if len(set(channels)) != len(channels):
                lines.append("two joints share a channel")
        if not isinstance(self.protocol, str) or self.protocol not in PROTOCOLS:
            lines.append(
                f"protocol {self.protocol!r} is unknown; use one of {', '.join(PROTOCOLS)}"
            )
        for name in ("audio_device", "camera"):
            value = getattr(self, name)
            if not (value is None or isinstance(value, str) or _is_integer(value)):
                lines.append(f"{name} must be a name, an index or null, not {value!r}")
        for name in ("serial_port", "sensor_port"):
            value = getattr(self, name)
            if not (value is None or isinstance(value, str)):
                lines.append(f"{name} must be a port name or null, not {value!r}")
        for name in ("acoustic_window_s", "confirm_window_s", "picture_interval_s"):
            value = getattr(self, name)
            if not (_is_number(value) and MIN_WINDOW_S <= value <= MAX_WINDOW_S):
                lines.append(
                    f"{name} must be a number of seconds, {MIN_WINDOW_S:g} to {MAX_WINDOW_S:g}"
                )
        if not (_is_integer(self.pictures_needed) and 1 <= self.pictures_needed <= MAX_PICTURES):
            lines.append(f"pictures_needed must be an integer 1..{MAX_PICTURES}")
        if not (_is_number(self.confidence_threshold) and 0 <= self.confidence_threshold <= 100):
            lines.append("confidence_threshold must be a percentage, 0..100")
        return lines

    def to_json(self) -> dict[str, Any]:
        return {"format": FORMAT, "version": VERSION, **asdict(self)}


def default_settings_path() -> Path:
    return config_dir() / "settings.json"


def load_settings(path: str | Path | None = None) -> Settings:
    """The settings in `path` (default `config_dir()/settings.json`); defaults if missing."""
    path = Path(path) if path is not None else default_settings_path()
    fix = "fix or delete it to get the defaults"
    if no_file_yet(path, "settings file", fix):
        return Settings()
    text = read_bounded_bytes(path, "settings file", MAX_FILE_BYTES)
    try:
        data = json_loads(text.decode("utf-8"), object_pairs_hook=unique_keys)
    except RecursionError as exc:
        raise ServantError(
            f"{path}: not a readable settings file (nested too deeply); {fix}"
        ) from exc
    except (UnicodeDecodeError, ValueError) as exc:
        raise ServantError(f"{path}: not a readable settings file ({exc}); {fix}") from exc
    if not isinstance(data, dict) or data.get("format", FORMAT) != FORMAT:
        raise ServantError(f"{path}: not a Servant settings file; {fix}")
    version = data.pop("version", VERSION)
    data.pop("format", None)
    if not _is_integer(version) or version < 1:
        raise ServantError(f"{path}: settings version {version!r} is not an integer version; {fix}")
    if version > VERSION:
        raise ServantError(
            f"{path}: settings version {version} is newer than this Servant reads; upgrade Servant"
        )
    known = {f.name for f in fields(Settings)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ServantError(f"{path}: unknown setting(s) {', '.join(map(repr, unknown))}; {fix}")
    try:
        if "joints" in data:
            data["joints"] = _joints(data["joints"])
    except ValueError as exc:
        raise ServantError(f"{path}: {exc}; {fix}") from exc
    settings = Settings(**data)
    problems = settings.problems()
    if problems:
        raise ServantError(f"{path}: {problems[0]}; {fix}")
    return settings


def _joints(raw: Any) -> list[Joint]:
    """The joints of a settings file; ValueError naming the first that is not one."""
    if not isinstance(raw, list):
        raise ValueError("joints must be a list of joints")
    names = [f.name for f in fields(Joint)]
    joints = []
    for i, joint in enumerate(raw, start=1):
        if not isinstance(joint, dict):
            raise ValueError(f"joint {i} is not an object with the joint's fields")
        missing = [n for n in names if n not in joint]
        unknown = sorted(set(joint) - set(names))
        if missing or unknown:
            what = [f"no {', '.join(missing)}"] if missing else []
            what += [f"unknown field(s) {', '.join(map(repr, unknown))}"] if unknown else []
            raise ValueError(f"joint {i} is malformed ({'; '.join(what)})")
        joints.append(Joint(**joint))
    return joints


def save_settings(settings: Settings, path: str | Path | None = None) -> Path:
    """Write the settings atomically; settings that could drive the arm unsafely are refused."""
    path = Path(path) if path is not None else default_settings_path()
    problems = settings.problems()
    if problems:
        raise ServantError(f"{path}: not saved: {problems[0]}")
    return atomic_write_json(path, settings.to_json())
