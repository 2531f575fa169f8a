"""The live log's line for each engine event (`ServantApp` writes them; the headless lines
are `servant_core.log_news`'s choice of the same events)."""

from __future__ import annotations

from typing import Any

from rich.markup import escape

from servant_core.event_text import SILENCE, arm_text, confidence_text, place
from servant_core.events import (
    AcousticPrediction,
    ArmState,
    Decision,
    DeviceStatus,
    ErrorEvent,
    Notice,
    SensePrediction,
    VisualPrediction,
)
from servant_tui.screens.live import device_message
from servant_tui.widgets.scene import leaned_text


def log_confidence(event: Any) -> str:
    """A confidence for the log, its unit bound to its number: the log wraps at spaces, and
    "(67.5" at the end of one row with "%)" alone on the next reads badly."""
    return confidence_text(event.confidence, event.confidence_unit).replace(" %", "%")


def log_text(event: Any) -> str | None:
    """The log's line for an event, or None for one the log does not show."""
    if isinstance(event, ArmState):
        if event.pose_of is not None:
            return escape(arm_text(event))
        if not event.connected:
            return "[red]arm not connected[/]"
        return "[bold red]arm ARMED[/]" if event.armed else "arm disarmed"
    if isinstance(event, Decision):
        leaned = leaned_text(event)
        because = f"; {leaned}" if leaned else ""
        if event.scene:
            confidence = log_confidence(event)
            return f"[bold green]{escape(event.line)} [/]({confidence}{because})"
        if leaned:
            return f"[yellow]{escape(event.line)} [/]({leaned})"
        return f"[yellow]{escape(event.line)}[/]"
    if isinstance(event, (AcousticPrediction, VisualPrediction)):
        verb = "hears" if isinstance(event, AcousticPrediction) else "sees"
        if event.scene is None:  # a confidence in no scene says nothing
            silent = isinstance(event, AcousticPrediction) and event.silent
            return f"{verb} {SILENCE if silent else place(None)}"
        confidence = log_confidence(event)
        return f"{verb} {escape(place(event.scene))} ({confidence})"
    if isinstance(event, SensePrediction):
        if event.scene is None:
            return f"{event.sense}: {place(None)}"
        confidence = log_confidence(event)
        return f"{event.sense}: {escape(place(event.scene))} ({confidence})"
    if isinstance(event, DeviceStatus):
        style = "dim" if event.ok else "red"
        return f"[{style}]{event.device}: {escape(device_message(event))}[/]"
    if isinstance(event, ErrorEvent):
        return f"[bold red]{escape(event.message)}[/]"
    if isinstance(event, Notice):
        return f"[cyan]{escape(event.message)}[/]"
    return None
