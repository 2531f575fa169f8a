"""Step 3 of teach mode: pictures of the place, their dominant colours shown."""

from __future__ import annotations

import threading

import numpy as np
from rich.text import Text
from textual import on, work
from textual.app import ComposeResult
from textual.widgets import Button, Label, Static

from servant_core.features.palette import dominant_colours
from servant_core.library import SceneLibrary
from servant_tui.messages import PictureTaken
from servant_tui.screens.teach.step import TeachStep, every_press
from servant_tui.widgets.colours import share_strip


class PicturesStep(TeachStep):
    """*Take picture* adds the camera's picture to the scene library."""

    STATUS = "#picture-status"

    def __init__(self, *, id: str) -> None:
        super().__init__(id=id)
        self.pictures = 0  # taken of the scene taught
        self._one_picture_at_a_time = threading.Lock()

    def compose(self) -> ComposeResult:
        yield Label("Take about six pictures of the place: what the camera sees is learnt.")
        yield every_press(Button("Take picture", id="take-picture", variant="primary"))
        yield Static(id="picture-status")

    def start_again(self) -> None:
        self.pictures = 0

    @on(Button.Pressed, "#take-picture")
    def start_picture(self) -> None:
        scene = self.attempt(self.wizard.need_scene)
        if scene is not None:
            self.take_picture(scene)

    # not exclusive: each press is a picture (an exclusive worker cancelled the one before it,
    # so three quick Enters took one); taken one at a time, each under its own time stamp
    @work(thread=True, group="picture", exit_on_error=False)
    def take_picture(self, scene: str) -> None:
        with self._one_picture_at_a_time:
            frame = self.app.engine.take_picture()
            path = SceneLibrary.at(self.app.library_root).add_picture(scene, frame)
        colours, shares = dominant_colours(frame)
        self.post_message(PictureTaken(path, colours, shares))

    @on(PictureTaken)
    def pictured(self, message: PictureTaken) -> None:
        self.pictures += 1
        text = Text(f"{self.pictures} picture(s) taken; last: {message.path.name}\n")
        text.append_text(share_strip(np.asarray(message.colours), np.asarray(message.shares), 40))
        self.query_one("#picture-status", Static).update(text)
        self.app.log_line(None, f"took {message.path}")
