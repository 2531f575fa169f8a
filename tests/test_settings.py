from __future__ import annotations

import json

import pytest

from servant_core.errors import ServantError
from servant_core.settings import (
    Joint,
    Settings,
    default_settings_path,
    load_settings,
    save_settings,
)


def test_missing_file_gives_safe_defaults():
    settings = load_settings()
    assert settings == Settings()
    assert [j.name for j in settings.joints] == ["shoulder", "elbow", "gripper"]
    assert settings.problems() == []
    assert (settings.acoustic_window_s, settings.confirm_window_s, settings.pictures_needed) == (
        30.0,
        20.0,
        3,
    )


def test_round_trip_through_the_config_dir():
    settings = Settings(
        serial_port="/dev/ttyACM0", protocol="firmata", camera=0, confidence_threshold=70.0
    )
    settings.joints[0] = Joint("shoulder", 9, -10, 80, 900, 1600, 20, 0)
    path = save_settings(settings)
    assert path == default_settings_path()
    assert load_settings() == settings


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("{not json", "not a readable settings file"),
        ('{"protocol": "dynamixel"}', "protocol 'dynamixel' is unknown"),
        ('{"colour": "blue"}', "unknown setting"),
        ('{"version": 99}', "newer than this Servant reads"),
        ('{"joints": [{"name": "x"}]}', r"joint 1 is malformed \(no channel, min_angle"),
        (
            '{"joints": [{"name": "x", "channel": 1, "min_angle": 90, "max_angle": 0,'
            ' "min_pulse_us": 1000,'
            ' "max_pulse_us": 2000, "max_speed_deg_s": 10, "home_angle": 0}]}',
            "min_angle must be below max_angle",
        ),
    ],
)
def test_a_broken_file_is_named_and_never_overwritten(tmp_path, content, message):
    path = tmp_path / "settings.json"
    path.write_text(content)
    with pytest.raises(ServantError, match=message) as info:
        load_settings(path)
    assert str(path) in str(info.value)
    assert path.read_text() == content


def test_unsafe_settings_are_not_saved(tmp_path):
    settings = Settings()
    settings.joints.append(Joint("wrist", 3, 0, 90, 1000, 1500, -5, 0))
    with pytest.raises(ServantError, match="max_speed_deg_s must be a number from 1 to"):
        save_settings(settings, tmp_path / "s.json")
    assert not (tmp_path / "s.json").exists()


def test_saved_file_is_plain_json(tmp_path):
    path = save_settings(Settings(), tmp_path / "s.json")
    data = json.loads(path.read_text())
    assert data["format"] == "servant-settings" and data["joints"][0]["name"] == "shoulder"


JOINT = {
    "name": "x",
    "channel": 1,
    "min_angle": 0,
    "max_angle": 90,
    "min_pulse_us": 1000,
    "max_pulse_us": 2000,
    "max_speed_deg_s": 10,
    "home_angle": 0,
}


def joints_file(**changes: object) -> str:
    return json.dumps({"joints": [{**JOINT, **changes}]})


@pytest.mark.parametrize(
    ("content", "message"),
    [
        # Issue 13, 8: each of these ended in a traceback or was accepted.
        ('{"joints": []}', "the arm needs at least one joint"),
        (joints_file(name=5), "a joint's name must be a non-empty text, not 5"),
        (joints_file(channel=True), "joint 'x': channel must be an integer 0..127"),
        ("[" * 100_000 + "]" * 100_000, r"not a readable settings file \(nested too deeply\)"),
        ('{"joints": 7}', "joints must be a list of joints"),
        ('{"joints": [3]}', "joint 1 is not an object"),
        ('{"joints": [{"name": [1]}]}', "joint 1 is malformed"),
        (joints_file(min_angle=True), "min_angle must be finite numbers"),
        ('{"serial_port": ["COM1"]}', "serial_port must be a port name or null"),
        ('{"sensor_port": 7}', "sensor_port must be a port name or null"),
        ('{"protocol": {"a": 1}}', "protocol .* is unknown"),
        ('{"acoustic_window_s": 1e400}', "acoustic_window_s must be a number of seconds"),
        ('{"confirm_window_s": true}', "confirm_window_s must be a number of seconds"),
        # Issue 24, re-probed: a window of 5e-324 s passed as "above 0".
        ('{"picture_interval_s": 5e-324}', r"picture_interval_s must be .* 0.1 to 600"),
        ('{"pictures_needed": 3.0}', "pictures_needed must be an integer"),
        ('{"confidence_threshold": NaN}', "confidence_threshold must be a percentage"),
        # Issue 13, 9: a version that is not an integer is not "newer".
        ('{"version": 1.0}', r"settings version 1.0 is not an integer version; fix or delete"),
        ('{"version": "2"}', "settings version '2' is not an integer version"),
        ('{"version": 0}', "settings version 0 is not an integer version"),
    ],
)
def test_bad_values_are_one_clear_line(tmp_path, content, message):
    path = tmp_path / "settings.json"
    path.write_text(content)
    with pytest.raises(ServantError, match=message) as info:
        load_settings(path)
    assert "\n" not in str(info.value)
    assert path.read_text() == content


def test_min_angle_above_max_angle_is_blamed_on_the_limits_alone(tmp_path):
    # Issue 10, 13: the home angle cannot lie between limits that are the wrong way round; only
    # the real fault is named.
    joint = Joint("elbow", 4, 100, 50, 1000, 1750, 45, 90)
    assert joint.problems() == ["joint 'elbow': min_angle must be below max_angle"]
    with pytest.raises(ServantError, match="min_angle must be below max_angle"):
        save_settings(Settings(joints=[joint]), tmp_path / "settings.json")
    assert not (tmp_path / "settings.json").exists()
