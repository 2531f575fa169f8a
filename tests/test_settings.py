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
        ('{"joints": [{"name": "x"}]}', "a joint is malformed"),
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
    with pytest.raises(ServantError, match="max_speed_deg_s must be a positive number"):
        save_settings(settings, tmp_path / "s.json")
    assert not (tmp_path / "s.json").exists()


def test_saved_file_is_plain_json(tmp_path):
    path = save_settings(Settings(), tmp_path / "s.json")
    data = json.loads(path.read_text())
    assert data["format"] == "servant-settings" and data["joints"][0]["name"] == "shoulder"
