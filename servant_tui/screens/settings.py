"""The settings screen: devices, the arm's joints and the fusion windows (platformdirs)."""

from __future__ import annotations

import dataclasses
from typing import Any

from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Horizontal, VerticalScroll
from textual.widgets import Button, Footer, Header, Input, Label, Select, Static

from servant_core.errors import ServantError
from servant_tui.screens.dialogs import UnsavedChanges
from servant_tui.screens.secondary import HELP_AND_QUIT, ServantScreen

DEVICE_FIELDS = (
    ("audio_device", "audio input", "sounddevice name or index; empty: the default input"),
    ("camera", "camera", "camera index, video file or image pattern; empty: index 0"),
    ("serial_port", "serial port", "e.g. /dev/ttyACM0; empty: no arm"),
    ("sensor_port", "sensor board", "motion/ambient: e.g. /dev/ttyUSB0 or a log folder"),
)
WINDOW_FIELDS = (
    ("acoustic_window_s", "acoustic window (s)"),
    ("confirm_window_s", "confirm window (s)"),
    ("pictures_needed", "pictures needed"),
    ("picture_interval_s", "picture interval (s)"),
    ("confidence_threshold", "confidence threshold (%)"),
)
# Each joint's fields and their column headings (narrow: eight columns fit in 80)
JOINT_FIELDS = {
    "channel": "channel",
    "min_angle": "min °",
    "max_angle": "max °",
    "min_pulse_us": "min µs",
    "max_pulse_us": "max µs",
    "max_speed_deg_s": "°/s",
    "home_angle": "home °",
}


def device_value(text: str) -> str | int | None:
    """An empty field is "the default", digits are an index, anything else a name or a path."""
    text = text.strip()
    if not text:
        return None
    return int(text) if text.isdigit() else text


def number(text: str, what: str, kind: type = float) -> Any:
    try:
        return kind(text.strip())
    except ValueError:
        words = "a whole number" if kind is int else "a number"
        raise ServantError(f"{what}: {text!r} is not {words}; type one") from None


class SettingsScreen(ServantScreen):
    BINDINGS = [
        Binding("escape", "back", "Back"),
        Binding("ctrl+s", "save", "Save"),
        *HELP_AND_QUIT,
    ]
    # The form opens on its first field, the audio input: README step 1 goes through the fields
    # in order (the scroll view took the focus, and what the user typed first went nowhere)
    AUTO_FOCUS = f"#{DEVICE_FIELDS[0][0]}"

    def compose(self) -> ComposeResult:
        from servant_core.settings import PROTOCOLS, load_settings

        settings = self.app.settings
        if settings is None:
            settings = self.app.settings = load_settings()
        self.loaded = settings
        yield Header()
        with VerticalScroll(id="settings"):
            yield Static("Devices", classes="section")
            with Grid(classes="form"):
                for name, label, hint in DEVICE_FIELDS:
                    value = getattr(settings, name)
                    yield Label(label)
                    yield Input("" if value is None else str(value), placeholder=hint, id=name)
                yield Label("protocol")
                yield Select(
                    [(p, p) for p in PROTOCOLS],
                    value=settings.protocol,
                    allow_blank=False,
                    id="protocol",
                )
            yield Static(
                "Joints: controller channel, angle limits (sent as the pulse widths beside "
                "them), speed, home",
                classes="section",
            )
            with Grid(classes="joints"):
                yield Label("joint")
                for heading in JOINT_FIELDS.values():
                    yield Label(heading)
                for joint in settings.joints:
                    yield Label(joint.name)
                    for field in JOINT_FIELDS:
                        yield Input(
                            f"{getattr(joint, field):g}", id=f"{joint.name}-{field}", type="number"
                        )
            yield Static("Fusion", classes="section")
            with Grid(classes="form"):
                for name, label in WINDOW_FIELDS:
                    yield Label(label)
                    yield Input(f"{getattr(settings, name):g}", id=name, type="number")
            with Horizontal(classes="buttons"):
                yield Button("Save", id="save", variant="primary")
                yield Button("Back", id="back")
        yield Footer()

    def on_mount(self) -> None:
        self.saved_form = self.form()

    def form(self) -> dict[str, Any]:
        """What every field shows, to tell whether the user changed anything since the last save
        (compared as shown: a number shown rounded is not a change)."""
        values: dict[str, Any] = {str(field.id): field.value for field in self.query(Input)}
        values["protocol"] = self.query_one("#protocol", Select).value
        return values

    def edited(self) -> Any:
        """The settings as the form shows them (not yet checked)."""
        values: dict[str, Any] = {}
        for name, _, _ in DEVICE_FIELDS:
            values[name] = device_value(self.query_one(f"#{name}", Input).value)
        values["protocol"] = self.query_one("#protocol", Select).value
        for name, label in WINDOW_FIELDS:
            kind = int if name == "pictures_needed" else float
            values[name] = number(self.query_one(f"#{name}", Input).value, label, kind)
        values["joints"] = [
            dataclasses.replace(
                joint,
                **{
                    field: number(
                        self.query_one(f"#{joint.name}-{field}", Input).value,
                        f"{joint.name} {heading}",
                        int if field == "channel" else float,
                    )
                    for field, heading in JOINT_FIELDS.items()
                },
            )
            for joint in self.loaded.joints
        ]
        return dataclasses.replace(self.loaded, **values)

    @on(Button.Pressed, "#save")
    def action_save(self) -> bool:
        """Save the form; False (and the reason said) if it could not be saved."""
        from servant_core.settings import save_settings

        try:
            settings = self.edited()
            path = save_settings(settings)
        except ServantError as error:
            self.app.report_error(error)
            return False
        except OSError as error:
            where = error.filename or "the config folder"
            self.app.report_error(
                ServantError(
                    f"settings: not saved, {where}: {error.strerror}; "
                    "check that the config folder is writable"
                )
            )
            return False
        self.app.settings = self.loaded = settings
        self.saved_form = self.form()
        self.app.log_line(None, f"settings saved to {path}")
        self.notify(f"Saved to {path}.", title="Settings")
        return True

    @on(Button.Pressed, "#back")
    def action_back(self) -> None:
        """Leave; with unsaved edits, ask first whether to save, discard or keep editing them."""
        if self.form() == self.saved_form:
            self.app.pop_screen()
            return

        def answered(choice: str | None) -> None:
            if choice == "discard" or (choice == "save" and self.action_save()):
                self.app.pop_screen()

        self.app.push_screen(UnsavedChanges(), answered)
