"""Every Textual message of the application, in one place.

Engine callbacks run on engine threads and workers on their own threads: both reach the UI only
by posting one of these to the app (`post_message` is thread-safe), never by touching a widget.
"""

from __future__ import annotations

from typing import Any

from textual.message import Message

from servant_core.events import SensorFrame, SpectrumFrame


class EngineEvent(Message):
    """Any engine event but spectrum and sensor frames (those have their own, droppable,
    messages)."""

    def __init__(self, event: Any) -> None:
        super().__init__()
        self.event = event


class SpectrumUpdate(Message):
    """A spectrum frame. They come ~30 a second: a newer one replaces one still queued."""

    def __init__(self, frame: SpectrumFrame) -> None:
        super().__init__()
        self.frame = frame

    def can_replace(self, message: Message) -> bool:
        return isinstance(message, SpectrumUpdate)


class SensorUpdate(Message):
    """A sample sense's latest readings (a few a second per sense): a newer frame of the same
    sense replaces one still queued."""

    def __init__(self, frame: SensorFrame) -> None:
        super().__init__()
        self.frame = frame

    def can_replace(self, message: Message) -> bool:
        return isinstance(message, SensorUpdate) and message.frame.sense == self.frame.sense


class RecordingDone(Message):
    """A teach window finished recording and was saved into the scene library: the sound at
    `path`, and `samples` the sample senses' logs of the same seconds written beside it."""

    def __init__(self, path: Any, seconds: float, samples: tuple[Any, ...] = ()) -> None:
        super().__init__()
        self.path = path
        self.seconds = seconds
        self.samples = samples


class RecordingStopped(Message):
    """A teach window's recording was stopped before its end (teach mode closed, or the app
    quit) and nothing of it was written. Posted to the app: the screen is gone by then."""

    def __init__(self, scene: str) -> None:
        super().__init__()
        self.scene = scene


class PictureTaken(Message):
    """A teach picture was taken and saved into the scene library."""

    def __init__(self, path: Any, colours: Any, shares: Any) -> None:
        super().__init__()
        self.path = path
        self.colours = colours
        self.shares = shares


class TrainingProgress(Message):
    """One step of the action learner's training: its error so far."""

    def __init__(self, step: int, total: int, error: float) -> None:
        super().__init__()
        self.step = step
        self.total = total
        self.error = error


class TrainingDone(Message):
    def __init__(self, learner: Any) -> None:
        super().__init__()
        self.learner = learner


class RetrainDone(Message):
    """The recognisers were retrained on the scene library."""

    def __init__(self, summary: str) -> None:
        super().__init__()
        self.summary = summary


class EvaluationDone(Message):
    def __init__(self, result: dict[str, Any]) -> None:
        super().__init__()
        self.result = result
