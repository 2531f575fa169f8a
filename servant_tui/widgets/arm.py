"""The arm pane: the link, armed or not, each joint's angle and the pose about to be sent."""

from __future__ import annotations

from rich.table import Table
from rich.text import Text
from textual.widgets import Static

from servant_core.events import ArmState
from servant_tui.widgets.text import bar


class ArmPane(Static):
    DEFAULT_CSS = """
    ArmPane { height: 1fr; }
    """

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.state: ArmState | None = None
        self.problem: str | None = None  # why there is no arm (the servo's status), if known

    def on_mount(self) -> None:
        self.update(self._render_state(), layout=False)

    def on_resize(self) -> None:
        self.update(self._render_state(), layout=False)

    def show_problem(self, message: str | None) -> None:
        """Say why no arm is attached (None: the servo works again)."""
        self.problem = message
        self.update(self._render_state(), layout=False)

    def show_state(self, state: ArmState) -> None:
        self.state = state
        self.set_class(state.armed, "-armed")
        self.update(self._render_state(), layout=False)

    def _render_state(self) -> Table:
        table = Table.grid(padding=(0, 1))
        table.add_column(style="bold", no_wrap=True, min_width=8)
        table.add_column(no_wrap=True)
        table.add_column(no_wrap=True, justify="right")
        state = self.state
        if self.problem and (state is None or not state.connected):
            why = Table.grid(padding=(0, 1))
            why.add_column(style="bold", no_wrap=True, min_width=8)
            why.add_column()  # the reason wraps in a narrow pane
            why.add_row("link", Text("○ no arm", "red"))
            why.add_row("", Text(self.problem, "grey70"))
            return why
        if state is None:
            table.add_row("link", Text("no arm state yet", "grey50"))
            return table
        link = (
            Text(f"● {state.port or '?'}", "green")
            if state.connected
            else Text("○ not connected", "red")
        )
        table.add_row("link", link, "")
        # the protocol is the line left out when the pane is one line short (80x24): the link,
        # whether it is armed and every joint matter more
        height = self.size.height
        if not height or height >= 3 + len(state.angles):
            table.add_row("protocol", Text(state.protocol or "–", "grey70"), "")
        armed = (
            Text(" ARMED ", "bold white on red")
            if state.armed
            else Text(" disarmed ", "black on grey70")
        )
        table.add_row("state", armed, "")
        bar_width = max(self.size.width - 22, 0)
        for joint, angle in state.angles.items():
            target = (state.target or {}).get(joint)
            arrow = Text(f"→{target:4.0f}°", "yellow") if target is not None else Text("")
            shown = Text.assemble(bar(angle / 180.0, bar_width, "cyan"), f" {angle:4.0f}°")
            table.add_row(joint[:8], shown, arrow)
        return table
