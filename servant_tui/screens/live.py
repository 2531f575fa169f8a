"""The live screen: spectrum and motion, colours, scene, arm and the event log, side by side."""

from __future__ import annotations

from collections.abc import Sequence

from rich.markup import escape
from textual.app import ComposeResult
from textual.cache import LRUCache
from textual.containers import Grid, Vertical
from textual.screen import Screen
from textual.widgets import Footer, Header, RichLog, Static

from servant_core.events import (
    ArmState,
    DeviceStatus,
    Palette,
    SensePrediction,
    SensorFrame,
    SpectrumFrame,
)
from servant_core.senses import SAMPLE_SENSES
from servant_tui.widgets.arm import ArmPane
from servant_tui.widgets.colours import ColoursPane
from servant_tui.widgets.motion import MotionPane
from servant_tui.widgets.scene import ScenePane
from servant_tui.widgets.spectrum import Spectrum

DEVICES = ("microphone", "camera", "servo")
SAMPLE_DEVICES = {s.device for s in SAMPLE_SENSES.values()}  # imu, ambient: the motion pane's


def device_message(status: DeviceStatus) -> str:
    """The status message without a repeat of the device's name in front."""
    return status.message.removeprefix(f"{status.device}: ")


class DeviceBar(Static):
    """One line saying which devices work and which are missing."""

    DEFAULT_CSS = """
    DeviceBar { height: 1; padding: 0 1; background: $boost; }
    """

    def __init__(self) -> None:
        super().__init__()
        self.statuses: dict[str, DeviceStatus] = {}

    def on_mount(self) -> None:
        self.update(self._render_statuses(), layout=False)

    def on_resize(self) -> None:
        self.update(self._render_statuses(), layout=False)

    def show_status(self, status: DeviceStatus) -> None:
        self.statuses[status.device] = status
        self.update(self._render_statuses(), layout=False)

    def _render_statuses(self) -> str:
        """Each device gets what its message needs while the line has room, and a share of what
        is left when it has not (`shares`): a long camera message must not push the servo off.
        A message too long for its share keeps its first clause whole (the problem; the advice
        after `;` is in the log and the notification) before it is cut short."""
        messages = {
            device: device_message(status) if (status := self.statuses.get(device)) else ""
            for device in DEVICES
        }
        needs = [len(device) + 3 + len(messages[device]) + 3 for device in DEVICES]
        rooms = shares(needs, max(self.size.width - 2, 12 * len(DEVICES)))
        parts = []
        for device, room in zip(DEVICES, rooms, strict=True):
            status = self.statuses.get(device)
            if status is None:
                parts.append(f"[dim]{device} …   [/]")
                continue
            message = fitted(messages[device], room - len(device) - 6)
            mark, style, body = ("✓", "green", "dim") if status.ok else ("✗", "bold red", "red")
            # spaces end the styled runs before them (see ServantApp.log_line)
            parts.append(f"[{style}]{device} {mark} [/][{body}]{escape(message)}   [/]")
        return "".join(parts).rstrip()


def shares(needs: Sequence[int], total: int) -> list[int]:
    """Widths for parts that need `needs`, within `total`: each gets its need if it is no more
    than an even share of what the others leave, the rest share what remains evenly."""
    given = [0] * len(needs)
    left, waiting = total, sorted(range(len(needs)), key=lambda i: needs[i])
    while waiting:
        share = left // len(waiting)
        i = waiting.pop(0)
        given[i] = min(needs[i], share)
        left -= given[i]
    return given


def fitted(message: str, room: int) -> str:
    """`message` within `room` characters: whole, else its first clause, else cut with "…"."""
    if len(message) <= room:
        return message
    clause = message.split("; ")[0]
    if len(clause) <= room:
        return clause
    return message[: max(room - 1, 0)] + "…"


class EventLog(RichLog):
    """The event log: the last `LOG_LINES` lines, and only the lines it may show cached.

    RichLog caches each line it has drawn under the line's number since the log began, 1,024 of
    them whatever `max_lines` keeps, so lines long dropped stayed cached: at the demo's 30 lines
    a minute the log grew for 34 minutes (about 6 MB in `tracemalloc`). A screenful is all the
    cache needs to spare repaints the cropping.
    """

    LOG_LINES = 300  # ten minutes of the demo's events: the log is bounded within the warm-up
    CACHED_LINES = 200  # more than a log pane has rows on any screen

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id, max_lines=self.LOG_LINES, markup=True, wrap=True, min_width=20)
        self._line_cache = LRUCache(self.CACHED_LINES)


class ShowsEvents:
    """A screen the app hands each engine event to while it is in the screen stack."""

    def show_event(self, event: object) -> None:
        raise NotImplementedError


class LiveScreen(Screen[None], ShowsEvents):
    """What the wearer sees while Servant runs; the base of the screen stack."""

    def __init__(self, sample_senses: Sequence[str] = ()) -> None:
        """`sample_senses`: the engine's sample senses (motion, ambient) in use, if any."""
        super().__init__()
        # Built here, not in compose: engine events may arrive before the screen is mounted.
        self.devices = DeviceBar()
        self.spectrum = Spectrum(id="spectrum")
        self.motion = MotionPane(sample_senses, id="motion")
        self.scene = ScenePane(id="scene", sample_senses=sample_senses)
        self.colours = ColoursPane(id="colours")
        self.arm = ArmPane(id="arm")
        self.log_view = EventLog(id="log")
        titles = (
            (self.spectrum, "Spectrum"),
            (self.motion, "Motion |a| m/s², 10 s"),
            (self.scene, "Scene"),
            (self.colours, "Colours"),
            (self.arm, "Arm"),
            (self.log_view, "Log"),
        )
        for pane, title in titles:
            pane.border_title = title

    def compose(self) -> ComposeResult:
        yield Header()
        yield self.devices
        with Grid(id="panes"):
            with Vertical(id="signals"):
                yield self.spectrum
                yield self.motion
            yield self.scene
            yield self.colours
            yield self.arm
            yield self.log_view
        yield Footer()

    def show_event(self, event: object) -> None:
        if isinstance(event, SpectrumFrame):
            self.spectrum.show_frame(event)
        elif isinstance(event, SensorFrame):
            self.motion.show_frame(event)
        elif isinstance(event, SensePrediction):
            self.motion.show_prediction(event)
            self.scene.show_event(event)
        elif isinstance(event, Palette):
            self.colours.show_palette(event)
        elif isinstance(event, ArmState):
            self.arm.show_state(event)
            self.arm.border_title = "Arm · ARMED" if event.armed else "Arm"
        elif isinstance(event, DeviceStatus):
            self.devices.show_status(event)
            if event.device == "servo":
                self.arm.show_problem(None if event.ok else device_message(event))
            elif event.device in SAMPLE_DEVICES:
                self.motion.show_status(event)
        else:
            self.scene.show_event(event)

    def write_log(self, line: str) -> None:
        self.log_view.write(line)
