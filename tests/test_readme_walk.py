"""The README's five steps, typed into a real terminal as a newcomer would.

tmux (120×40, a server of the test's own) runs a shell; the test types the README's commands
into it (`source .venv/bin/activate`, `servant emulate-servo --link …` for the arm, `servant`)
and the keys its steps name, and reads the screen with `capture-pane`. Everything is real:
empty data and config dirs, the virtual microphone (PortAudio's default input, the places are
played into it), an image sequence as the camera (the test swaps the pictures as the wearer
walks) and the emulator on a pty, whose printed moves are the arm's proof. The camera is chosen
in Settings while the app runs (step 1: no restart).

1. Connect: `s`, the camera and the arm's port typed into Settings, Ctrl-S, escape: the status
   line says ✓ for both.
2. Teach two places by keyboard: a name, Enter; Enter on *Record 5 s* six times (what teach mode
   asks for); Ctrl-N, Enter on *Take picture* three times; Ctrl-N, the angles, *Add sample*;
   *Teach another scene*.
3. Retrain: Ctrl-N to *Train*, Enter (the poses), Enter (*Retrain recognisers*).
4. Arm: escape, `a`: ARMED.
5. Watch: walk into the café: `CafeScene detected`, and the emulator receives the café's pose.

Then the README's command line (issue 39), in the same shell, on what teach mode left:

6. `servant train LIBRARY`, its first example, on the library teach mode wrote: the model teach
   mode saved is not replaced (one line naming --force and -o, exit status 2), and still loads.
7. `servant run --headless --arm` loads that model. The wearer walks onto the street, past a gym
   never taught, into the café: one line for each decision, the gym explained once with how to
   teach it, and the controller receives one pose per decision, never a pose it holds already.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import time
import uuid
from pathlib import Path

import cv2
import numpy as np
import pytest

from servant_core.demo.scenes import synth_picture
from servant_core.engine import NO_MODEL
from servant_core.library import TEACH_WINDOWS
from servant_core.modelfile import load_model
from tests.test_live_path import POSES, scene_sound
from tests.test_microphone import play
from tests.test_microphone import virtual_mic as virtual_mic  # a fixture

ROOT = Path(__file__).resolve().parents[1]
ACTIVATE = ROOT / ".venv" / "bin" / "activate"
PLACES = {"cafe": "coffee", "street": "street"}  # the place's name: the synthesised scene

FRAMES = 3  # the camera's image sequence

pytestmark = pytest.mark.skipif(shutil.which("tmux") is None, reason="tmux is not installed")


def show(scene: str, folder: Path, seed: int) -> None:
    """What the camera sees from now on (each frame replaced atomically)."""
    for k in range(FRAMES):
        ok, png = cv2.imencode(".png", synth_picture(scene, np.random.default_rng([seed, k])))
        assert ok
        tmp = folder / f".frame_{k:02d}.png"
        tmp.write_bytes(png.tobytes())
        os.replace(tmp, folder / f"frame_{k:02d}.png")


class Terminal:
    """A tmux server of its own (`-L`), so the environment is this test's, not a server's that
    another test or user started; one window per shell."""

    def __init__(self, env: dict[str, str]) -> None:
        self.socket = f"servant-readme-{uuid.uuid4().hex[:8]}"
        self.env = env

    def tmux(self, *args: str) -> str:
        return subprocess.run(
            ["tmux", "-L", self.socket, "-f", "/dev/null", *args],
            capture_output=True,
            text=True,
            check=True,
            env=self.env,
        ).stdout

    def open(self, window: str) -> None:
        """A new shell window at 120×40 in the repository, as a user's terminal."""
        shell = "bash --norc --noprofile"
        if window == "app":
            self.tmux("new-session", "-d", "-s", "readme", "-n", window, "-x", "120", "-y", "40",
                      "-c", str(ROOT), shell)  # fmt: skip
        else:
            self.tmux("new-window", "-d", "-t", "readme", "-n", window, "-c", str(ROOT), shell)

    def type(self, window: str, text: str, enter: bool = True) -> None:
        """Text, then a moment, as a person types: a key sent in the same instant as the text
        reaches the app in the same read (a Tab right after a path was lost in a loaded run)."""
        self.tmux("send-keys", "-t", f"readme:{window}", "-l", text)
        time.sleep(0.3)
        if enter:
            self.keys(window, "Enter")

    def keys(self, window: str, *keys: str) -> None:
        """Named keys (Enter, Tab, C-n, Escape), each a moment after the last, as typed."""
        for key in keys:
            self.tmux("send-keys", "-t", f"readme:{window}", key)
            time.sleep(0.3)

    def screen(self, window: str, start: str = "-200") -> str:
        """The window's text from `start` (a line of its history; "-": all of it) to its end."""
        return self.tmux("capture-pane", "-p", "-J", "-S", start, "-t", f"readme:{window}")

    def clear(self, window: str) -> None:
        """An empty screen and history: what follows is the next command's alone."""
        self.type(window, "clear")
        self.tmux("clear-history", "-t", f"readme:{window}")

    def run(self, window: str, command: str, seconds: float) -> list[str]:
        """`command` typed at the window's prompt, and the lines it printed once the prompt
        shows again; fails showing the screen."""
        deadline = time.monotonic() + seconds
        prompt = self.screen(window).rstrip().rpartition("\n")[2]
        while not prompt.endswith(("$", "#")):  # typed before the shell waits, it is echoed twice
            if time.monotonic() > deadline:
                raise AssertionError(f"no prompt in {window}:\n{self.screen(window)}")
            time.sleep(0.5)
            prompt = self.screen(window).rstrip().rpartition("\n")[2]
        self.type(window, command)
        lines: list[str] = []
        while time.monotonic() < deadline:
            lines = [line.rstrip() for line in self.screen(window).splitlines()]
            typed = [i for i, line in enumerate(lines) if line.endswith(f"{prompt} {command}")]
            after = range(typed[-1] + 1, len(lines)) if typed else range(0)
            end = next((i for i in after if lines[i].startswith(prompt)), None)
            if end is not None:
                return lines[typed[-1] + 1 : end]
            time.sleep(0.5)
        shown = "\n".join(lines)
        raise AssertionError(f"{command!r} still runs in {window} after {seconds:g} s:\n{shown}")

    def wait_for(self, window: str, pattern: str, seconds: float) -> str:
        """The screen once `pattern` (a regular expression) is on it; fails showing the screen."""
        deadline = time.monotonic() + seconds
        screen = ""
        while time.monotonic() < deadline:
            screen = self.screen(window)
            if re.search(pattern, screen):
                return screen
            time.sleep(0.5)
        raise AssertionError(f"{pattern!r} not on {window}'s screen after {seconds:g} s:\n{screen}")

    def wait_for_shell(self, window: str, seconds: float) -> None:
        """The window's shell runs no command any more (the one it ran has ended)."""
        deadline = time.monotonic() + seconds
        command = ""
        while time.monotonic() < deadline:
            command = self.tmux(
                "display-message", "-p", "-t", f"readme:{window}", "#{pane_current_command}"
            ).strip()
            if command == "bash":
                return
            time.sleep(0.5)
        raise AssertionError(f"{window} still runs {command!r}:\n{self.screen(window)}")

    def close(self) -> None:
        subprocess.run(["tmux", "-L", self.socket, "kill-server"], capture_output=True)


def teach_place(term: Terminal, place: str, pose: dict[str, float]) -> None:
    """README step 2 for one place, by keyboard; the test has put its sound and pictures on."""
    term.wait_for("app", r"Pick the scene you are in", 20)
    term.type("app", place)  # the name field has the focus; Enter: *Use this scene*
    term.wait_for("app", rf"teaching {place}", 10)
    for n in range(1, TEACH_WINDOWS + 1):
        term.keys("app", "Enter")  # *Record 5 s*
        term.wait_for("app", rf"{n} window\(s\) recorded", 30)
    term.keys("app", "C-n")
    term.wait_for("app", r"Take about six pictures of the place", 10)
    for n in (1, 2, 3):
        term.keys("app", "Enter")  # *Take picture*
        term.wait_for("app", rf"{n} picture\(s\) taken", 15)
    term.keys("app", "C-n")
    term.wait_for("app", r"The arm's pose for this scene", 10)
    for angle in pose.values():  # the first joint's field has the focus, the others follow
        term.type("app", f"{angle:g}", enter=False)
        term.keys("app", "Tab")
    term.keys("app", "Tab", "Enter")  # past *Use the arm's pose*: *Add sample*
    term.wait_for("app", rf"{place}\s+shoulder {pose['shoulder']:g}°", 10)  # the samples list


def moves(term: Terminal) -> list[str]:
    """The moves the emulator has said it received (`servant emulate-servo`: one line a move,
    however many steps the link sent it in), oldest first."""
    return [line for line in term.screen("arm").splitlines() if "received a move: " in line]


def pose_move(pose: dict[str, float]) -> str:
    """The emulator's words for a move to `pose`, as a regular expression."""
    return ".*".join(rf"{joint} {round(angle)}° " for joint, angle in pose.items())


def wait_for_move(term: Terminal, pose: dict[str, float], after: int, seconds: float) -> None:
    """Until the emulator says it received a move to `pose` after its first `after` moves."""
    deadline = time.monotonic() + seconds
    while not any(re.search(pose_move(pose), move) for move in moves(term)[after:]):
        if time.monotonic() > deadline:
            raise AssertionError(f"no move to {pose} after {seconds:g} s: {moves(term)[after:]}")
        time.sleep(0.5)


@pytest.mark.timeout(660)
def test_the_readmes_five_steps_then_its_command_line_in_a_real_terminal(tmp_path, virtual_mic):
    env = {
        **os.environ,
        "SERVANT_DATA_DIR": str(tmp_path / "data"),
        "SERVANT_CONFIG_DIR": str(tmp_path / "config"),
        "PS1": "$ ",
    }
    camera = tmp_path / "camera"
    camera.mkdir()
    show("coffee", camera, seed=1)  # the camera is plugged in, but the settings name none
    arm = tmp_path / "arm"
    sounds = {p: scene_sound(s, tmp_path / f"{p}.wav", seconds=120.0) for p, s in PLACES.items()}
    poses = {"cafe": POSES["coffee"], "street": POSES["street"]}
    term = Terminal(env)
    player = None
    try:
        term.open("app")
        term.open("arm")
        for window in ("app", "arm"):
            if ACTIVATE.exists():  # the README: without `make install`, activate the venv
                term.type(window, "source .venv/bin/activate")
        term.type("arm", f"servant emulate-servo --link {arm}")
        term.wait_for("arm", r"Emulating a", 30)

        # 1. Connect: an empty config names no camera (index 0: none here) and no arm.
        term.type("app", "servant")
        term.wait_for("app", r"camera ✗.*servo ✗", 60)
        term.keys("app", "s")
        term.wait_for("app", r"Devices", 10)
        time.sleep(1.0)  # as a person reads the form before typing
        term.keys("app", "Tab")  # from the audio input (empty: the default) to the camera
        term.type("app", str(camera / "frame_%02d.png"), enter=False)
        term.keys("app", "Tab")
        term.type("app", str(arm), enter=False)
        term.keys("app", "C-s")
        term.wait_for("app", r"Saved to", 10)
        term.keys("app", "Escape")
        term.wait_for("app", r"camera ✓.*servo ✓", 30)  # no restart

        # 2. Teach two places.
        term.keys("app", "t")
        for n, place in enumerate(PLACES):
            show(PLACES[place], camera, seed=10 + n)
            player = play(sounds[place])
            teach_place(term, place, poses[place])
            if n == 0:
                term.keys("app", "Tab", "Enter")  # *Teach another scene*
            player.kill()

        # 3. Retrain: the Train step, Train, then Retrain (the focus goes there).
        term.keys("app", "C-n")
        term.wait_for("app", r"Learn scene → pose", 10)
        term.keys("app", "Enter")
        term.wait_for("app", r"Next: Retrain recognisers", 90)
        term.keys("app", "Enter")
        term.wait_for("app", r"retrained on cafe, street", 120)

        # 4. Arm.
        term.keys("app", "Escape")
        term.wait_for("app", r"Spectrum", 10)
        term.keys("app", "a")
        term.wait_for("app", r"ARMED", 10)

        # 5. Watch: into the café.
        show("coffee", camera, seed=99)
        player = play(sounds["cafe"])
        term.wait_for("app", r"CafeScene detected", 60)
        shoulder, elbow = (round(poses["cafe"][j]) for j in ("shoulder", "elbow"))
        term.wait_for("arm", rf"received a move: shoulder {shoulder}°.*elbow {elbow}°", 30)

        term.keys("app", "q")
        term.wait_for_shell("app", 20)  # the app quit cleanly
        player.kill()

        # 6. `servant train LIBRARY`, the README's first command-line example, on the library
        # teach mode wrote: it replaced the model taught in the app, silently (issue 39 item 1).
        data = tmp_path / "data"
        library, model = data / "library", data / "model.npz"
        taught = model.read_bytes()
        said = term.run("app", f"servant train {library}", 60)
        assert len(said) == 1, said  # one line: what is wrong, what to do
        assert said[0].startswith(f"servant: error: {model}: holds the model"), said
        assert "-o FILE" in said[0] and "--force" in said[0], said
        assert term.run("app", 'echo "exit status $?"', 10) == ["exit status 2"]
        assert model.read_bytes() == taught and not model.with_name("model.1.npz").exists()
        recognisers = load_model(model)  # loadable: the places teach mode taught
        assert all(r.scenes_ == sorted(PLACES) for r in recognisers.values()), recognisers

        # 7. Headless, armed, with that model: the street, a gym never taught, the café. Each
        # state is to be said when it begins: the issue saw `CafeScene detected`, `arm armed,
        # at …` and `unknown audio (audio-N)` at every 5 s window, and the café's pose sent to
        # the controller again at each (items 3, 4). The street comes first: the arm stands at
        # the café's pose the app left it in.
        sounds["gym"] = scene_sound("gym", tmp_path / "gym.wav", seconds=90.0)
        before = len(moves(term))
        term.clear("app")
        term.type("app", "servant run --headless --arm")
        term.wait_for("app", r"arm armed, at", 60)
        for place, scene, seed in [
            ("street", "street", 98),
            ("gym", "gym", 97),
            ("cafe", "coffee", 96),
        ]:
            show(scene, camera, seed=seed)
            player = play(sounds[place])
            if place in poses:
                term.wait_for("app", rf"{place.title()}Scene detected", 60)
                wait_for_move(term, poses[place], before, 30)
            else:  # said once the place has held 30 s
                term.wait_for("app", r"a place Servant was not taught", 75)
            time.sleep(11.0)  # two more 5 s windows there: each said it all again, and resent
            player.kill()
        term.keys("app", "C-c")
        term.wait_for_shell("app", 20)

        run = term.screen("app", start="-")
        lines = run.splitlines()
        assert NO_MODEL not in run and "Traceback" not in run, run  # the model was loaded
        for place in poses:
            decided = [line for line in lines if f"{place.title()}Scene detected" in line]
            assert len(decided) == 1, run
            moved = [line for line in lines if f"arm moved to {place}'s pose" in line]
            assert len(moved) == 1, run
        assert len([line for line in lines if "arm armed, at" in line]) == 1, run
        unknown = [line for line in lines if re.search(r"\baudio-\d", line)]
        assert len(unknown) == 1, run
        assert "a place Servant was not taught" in unknown[0], unknown
        assert "teach mode, key t" in unknown[0] and f"{library}/<name>/" in unknown[0], unknown
        assert f"servant train {library} --force" in unknown[0], unknown
        received = moves(term)[before:]
        assert len(received) == 2, received  # the street's pose, then the café's: once each
        assert re.search(pose_move(poses["street"]), received[0]), received
        assert re.search(pose_move(poses["cafe"]), received[1]), received
        assert model.read_bytes() == taught
    finally:
        if player is not None:
            player.kill()
        term.close()
