"""The open set's question on the live screen, "What is this place?": asked at most so often,
moved to the newest unknown window while open, withdrawn once the place is known after all."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rich.markup import escape

from servant_core.event_text import place
from servant_core.events import UnknownScene
from servant_tui.screens.dialogs import LabelPrompt
from servant_tui.widgets.scene import heard_by
from servant_tui.widgets.text import clock

if TYPE_CHECKING:
    from servant_tui.app import ServantApp

# How often an unknown place may interrupt the wearer with a question, at most; one that the
# wearer skips keeps quiet for longer. A place heard while teaching or editing is only logged.
PROMPT_EVERY_S = 60.0
PROMPT_AFTER_SKIP_S = 300.0
# An open question closes by itself once the sense asked about has named taught places this long
# (three 5 s windows in a row): the wearer walked into a place Servant knows. Not at one window
# that happens to name one: at a building site heard as a café every fourth window, the question
# vanished 5 s after it was asked, each time, before the wearer could answer it.
WITHDRAW_AFTER_S = 10.0


class PlaceQuestion:
    """The app's question about unknown places: the open prompt, if any, and when the next may
    be asked. The answer is the app's to label (`ServantApp.label_unknown`)."""

    def __init__(self, app: ServantApp) -> None:
        self._app = app
        self.prompt: LabelPrompt | None = None  # the open "What is this place?"
        self.quiet_until: float | None = None  # engine time before which no place is asked about
        self.deferred = False  # an unknown place was met behind another screen, and logged
        self.named_since: float | None = None  # since when the sense asked about names a place

    def ask(self, event: UnknownScene) -> None:
        """Ask the wearer to name an unknown place, unless a question is open, another screen
        (teach mode, the library, settings) is in front, or one was asked or skipped lately.
        While a question is open, the engine asking again about the same sense (the place still
        unknown) moves the answer to its newest window: the engine keeps only its last few
        unknown windows, and a wearer answering after a minute and a half labelled a window
        already dropped ("no such unknown window")."""
        app = self._app
        if self.prompt is not None:
            if event.sense == self.prompt.event.sense:
                self.prompt.event = event
            return
        # the log says so when it asks, or once when another screen keeps it from asking; not
        # at every window the engine would ask at (the lines "hears an unknown place" say those)
        nearest = f", nearest {escape(event.nearest_scene)}" if event.nearest_scene else ""
        said = f"[magenta]unknown place ({event.sense}{nearest})"
        if app.screen is not app.live:
            if not self.deferred:
                self.deferred = True
                app.log_line(event.t, f"{said}: asked on the live screen[/]")
            return
        if self.quiet_until is not None and event.t < self.quiet_until:
            return
        self.deferred = False
        self.named_since = None
        prompt = self.prompt = LabelPrompt(event, sorted(app.known_scenes))
        app.log_line(event.t, f"{said}: asking for a label[/]")

        def answered(scene: str | None) -> None:
            self.prompt = None
            skipped = scene is None and not prompt.withdrawn
            self.quiet_until = event.t + (PROMPT_AFTER_SKIP_S if skipped else PROMPT_EVERY_S)
            if skipped:  # Escape or "Not now": the pane stops saying it is asking
                app.live.scene.not_now(self.quiet_until)
                app.log_line(event.t, f"Not now: no question before {clock(self.quiet_until)}")
            if scene:
                app.label_unknown(prompt.event.window_id, scene)

        app.push_screen(prompt, answered)

    def withdraw_if_stale(self, event: Any) -> None:
        """An open "What is this place?" is stale once the sense it asked for has named taught
        places for `WITHDRAW_AFTER_S`: the wearer walked on (or the place was known after all).
        The question closes by itself, said in the log; no answer is taken for a skip. It stays
        while the wearer has begun typing an answer, and a place decided on one window does not
        close it: the label is for the stretch asked about, which is still unknown."""
        prompt = self.prompt
        if prompt is None or prompt.withdrawn or not heard_by(event, prompt.event.sense):
            return
        if not event.scene:
            self.named_since = None
            return
        if self.named_since is None:
            self.named_since = event.t
        if event.t - self.named_since < WITHDRAW_AFTER_S or prompt.answering:
            return
        self._app.log_line(
            event.t, f"[magenta]question withdrawn: this is {escape(place(event.scene))} now[/]"
        )
        prompt.withdraw()
