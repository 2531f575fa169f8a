"""Modal dialogs: the help screen, naming an unknown place, and asking for a scene or a yes."""

from __future__ import annotations

from textual import on
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical, VerticalScroll
from textual.screen import ModalScreen
from textual.suggester import SuggestFromList
from textual.widgets import Button, Input, Label, Markdown

from servant_core.events import UnknownScene

HELP = """\
# Servant

Servant listens and looks, names the scene you are in, and moves the arm to the pose you taught
for it. The **live** screen shows:

| pane | what it shows |
|---|---|
| Spectrum | the microphone's spectrum, log frequency, dB re full scale |
| Motion | acceleration over 10 s (gravity fills half), light, warmth, pressure (`--imu PORT`) |
| Colours | the frame's dominant colours and shares, beside the training palette they matched |
| Scene | what each sense says, the confirmation window, the decisions and what they leaned on |
| Arm | the serial link, armed or not, each joint's angle and the pose about to be sent |
| Log | every decision (`CoffeeScene detected`, `No scene detected`) and every problem |

| key | does |
|---|---|
| `a` | arm or disarm (the arm moves only when armed) |
| `t` | teach mode: scene, sound, pictures, pose, train, test |
| `l` | the scene library: samples, relabel, delete, retrain, evaluate |
| `s` | settings: devices, joints, fusion windows |
| `ctrl+p` | the command palette |
| `escape` | back to the live screen |
| `q` | quit (stops capture, closes the serial port); `ctrl+q` while typing in a field |
"""


class HelpScreen(ModalScreen[None]):
    BINDINGS = [Binding("escape,question_mark,f1", "dismiss", "Close")]

    def compose(self) -> ComposeResult:
        with Vertical(id="help", classes="dialog"):
            # focused, so that up/down, page up/down, home and end scroll it from the keyboard
            with VerticalScroll(id="help-text"):
                yield Markdown(HELP)
            yield Button("Close", id="close", variant="primary")

    def on_mount(self) -> None:
        self.query_one("#help-text").focus()

    @on(Button.Pressed, "#close")
    def close(self) -> None:
        self.dismiss()


class LabelPrompt(ModalScreen[str | None]):
    """The engine met a place it does not know: ask the wearer what it is."""

    BINDINGS = [Binding("escape", "dismiss", "Not now")]

    def __init__(self, event: UnknownScene, known_scenes: list[str]) -> None:
        super().__init__()
        self.event = event
        self.known_scenes = known_scenes
        self.withdrawn = False  # closed by the app: the place is known now, nothing to answer

    def withdraw(self) -> None:
        self.withdrawn = True
        self.dismiss(None)

    @property
    def answering(self) -> bool:
        """Whether the wearer has begun typing a name (the question then stays open); False
        before the dialog is drawn."""
        fields = self.query("#scene").results(Input)
        return any(field.value.strip() for field in fields)

    def compose(self) -> ComposeResult:
        sense = {"audio": "heard", "image": "saw"}.get(
            self.event.sense, f"felt ({self.event.sense})"
        )
        nearest = self.event.nearest_scene or "nothing known"
        with Vertical(id="label-prompt", classes="dialog"):
            yield Label(f"Servant {sense} a place it does not know (nearest: {nearest}).")
            yield Label("What is this place? The sample joins that scene in the library.")
            yield Input(
                placeholder="scene name, e.g. cafe",
                suggester=SuggestFromList(self.known_scenes, case_sensitive=False),
                id="scene",
            )
            with Horizontal(classes="buttons"):
                yield Button("Label", id="label", variant="primary")
                yield Button("Not now", id="skip")

    @on(Input.Submitted)
    @on(Button.Pressed, "#label")
    def label(self) -> None:
        scene = self.query_one(Input).value.strip()
        if scene:
            self.dismiss(scene)
        else:
            self.notify("Type a scene name, or press Not now.", severity="warning")

    @on(Button.Pressed, "#skip")
    def skip(self) -> None:
        self.dismiss(None)


class ScenePrompt(ModalScreen[str | None]):
    """Ask for a scene name (relabelling a sample)."""

    BINDINGS = [Binding("escape", "dismiss", "Cancel")]

    def __init__(self, question: str, scenes: list[str], value: str = "") -> None:
        super().__init__()
        self.question = question
        self.scenes = scenes
        self.value = value

    def compose(self) -> ComposeResult:
        with Vertical(classes="dialog"):
            yield Label(self.question)
            yield Input(self.value, suggester=SuggestFromList(self.scenes, case_sensitive=False))
            with Horizontal(classes="buttons"):
                yield Button("OK", id="ok", variant="primary")
                yield Button("Cancel", id="cancel")

    @on(Input.Submitted)
    @on(Button.Pressed, "#ok")
    def ok(self) -> None:
        self.dismiss(self.query_one(Input).value.strip() or None)

    @on(Button.Pressed, "#cancel")
    def cancel(self) -> None:
        self.dismiss(None)


class Confirm(ModalScreen[bool]):
    BINDINGS = [Binding("escape", "dismiss(False)", "Cancel")]

    def __init__(self, question: str) -> None:
        super().__init__()
        self.question = question

    def compose(self) -> ComposeResult:
        with Vertical(classes="dialog"):
            yield Label(self.question)
            with Horizontal(classes="buttons"):
                yield Button("Yes", id="yes", variant="error")
                yield Button("No", id="no", variant="primary")

    @on(Button.Pressed)
    def answer(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")


class UnsavedChanges(ModalScreen[str]):
    """Leaving a form with unsaved edits: "save", "discard" or "keep" (editing)."""

    BINDINGS = [Binding("escape", "dismiss('keep')", "Keep editing")]

    def compose(self) -> ComposeResult:
        with Vertical(id="unsaved", classes="dialog"):
            yield Label("The settings have unsaved changes.")
            with Horizontal(classes="buttons"):
                yield Button("Save", id="save", variant="primary")
                yield Button("Discard", id="discard", variant="error")
                yield Button("Keep editing", id="keep")

    @on(Button.Pressed)
    def answer(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id)
