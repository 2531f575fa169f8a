"""Step 1 of teach mode: the scene taught, one already known or a new name."""

from __future__ import annotations

from rich.markup import escape
from textual import events, on
from textual.app import ComposeResult
from textual.widgets import Button, Input, Label, Select

from servant_core.errors import ServantError
from servant_core.place_names import place_name
from servant_tui.screens.teach.step import TeachStep


class KnownScenes(Select[str]):
    """The known scenes' list, where teach mode opens once a scene is known. A name typed at it
    goes into the new name's field, and the Enter after it names the scene: a returning wearer
    typing the new place's name (the README: "press t, name it") saw nothing happen, the list
    took the letters and Enter opened it. Keys come from the terminal in a burst, all given to
    the list before the first moves the focus, so every letter the list gets is passed on."""

    def passes_on(self, character: str | None) -> bool:
        """Whether a key typed here goes to the name's field: a letter, not Enter, space or an
        arrow (they still open the list), and not while the list is open."""
        typed = character or ""
        return not self.expanded and typed.isprintable() and bool(typed.strip())

    def check_consume_key(self, key: str, character: str | None = None) -> bool:
        # the letters are the name's, like a field's: the footer offers no key they type
        return self.passes_on(character)

    def on_key(self, event: events.Key) -> None:
        if not self.passes_on(event.character):
            return
        field = self.screen.query_one("#new-scene", Input)
        self.screen.set_focus(field)
        field.insert_text_at_cursor(event.character or "")
        event.stop()


class SceneStep(TeachStep):
    """The scene's name, by `place_name`'s rule: a known place in its spelling, or a new one."""

    def __init__(self, scenes: list[str], *, id: str) -> None:
        super().__init__(id=id)
        self._scenes = scenes

    def compose(self) -> ComposeResult:
        yield Label("Pick the scene you are in, or name a new one.")
        yield KnownScenes([(s, s) for s in self._scenes], prompt="known scenes", id="known")
        yield Input(
            # README step 2's name: the log says CafeScene (a CoffeeScene was CoffeeSceneScene)
            placeholder="new scene name, e.g. cafe",
            id="new-scene",
            select_on_focus=False,  # a letter the known scenes passed on stays
        )
        yield Button("Use this scene", id="use-scene", variant="primary")

    @on(Input.Submitted, "#new-scene")
    @on(Button.Pressed, "#use-scene")
    def use_scene(self) -> None:
        typed = self.query_one("#new-scene", Input).value.strip()
        known = self.query_one("#known", Select).value
        scene = typed or (known if isinstance(known, str) else None)
        if not scene:
            self.notify("Pick a known scene or type a new name.", severity="warning")
            return
        wizard = self.wizard
        try:
            scene = place_name(scene, wizard.root, wizard.known_scenes())
        except ServantError as error:
            self.app.report_error(error)
            return
        wizard.scene = scene
        wizard.sub_title = f"teaching {scene}"
        self.app.log_line(None, f"teaching scene {escape(scene)}")
        wizard.go("sound")

    def start_again(self) -> None:
        self.query_one("#new-scene", Input).value = ""
        self.query_one("#known", Select).set_options((s, s) for s in self.wizard.known_scenes())
