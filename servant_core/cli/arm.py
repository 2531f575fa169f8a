"""The arm on the command line: `servant teach`, `servant servo ...` and `servant emulate-servo`."""

from __future__ import annotations

import argparse
import math
import re
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from servant_core.actions.learner import (
    ActionLearner,
    check_learner_output,
    default_learner_path,
)
from servant_core.actions.records import (
    TeachRecord,
    append_record,
    check_records_output,
    default_records_path,
    label_scores,
    load_records,
)
from servant_core.cli import emit, serve_until_stopped, terminal_text, write_line
from servant_core.cli.options import bounded_int, finite_float
from servant_core.errors import ServantError
from servant_core.event_text import pose_text
from servant_core.place_names import place_key, place_name
from servant_core.pty_port import announce, announced_ports
from servant_core.servo import PROTOCOLS
from servant_core.servo.calibration import clamp_pose, pulse_to_angle
from servant_core.servo.emulator import ServoEmulator, start_emulator
from servant_core.servo.link import MAX_RECORD_S, MAX_TIMEOUT_S, ManualClock, ServoLink, seconds
from servant_core.settings import Joint, Settings, load_settings

RECORD_SECONDS = 3.0
MAX_ITERATIONS = 100_000  # the paper's session trains 3000; a hundred thousand is minutes already
MAX_EMULATE_S = 7 * 24 * 3600.0


def register(subparsers: argparse._SubParsersAction) -> None:
    teach = subparsers.add_parser(
        "teach",
        description="A line-oriented session on stdin/stdout. Training phase: a scene label, then "
        "the action (an angle for --joint, `joint=angle ...`, or `record [seconds]` to read the "
        "pose the arm is guided into); an empty label ends it. The learner trains, printing its "
        "error, then the prediction phase answers a scene label with the pose. A typed label "
        "counts as certain: one-hot scores over the known scenes, for both senses.",
    )
    _link_options(teach)
    teach.add_argument(
        "--records", help="teach record file (default: the data dir's teach/records.json)"
    )
    teach.add_argument("--learner", help="learner file (default: the data dir's teach/learner.npz)")
    teach.add_argument("--joint", help="the joint a bare number moves (default: the first joint)")
    teach.add_argument(
        "--iterations",
        type=bounded_int(1, MAX_ITERATIONS),
        default=3000,
        help="training iterations",
    )
    teach.add_argument(
        "--predict-only",
        action="store_true",
        help="skip training: load the saved learner and ask it",
    )
    teach.set_defaults(handler=run_teach)

    servo = subparsers.add_parser("servo")
    commands = servo.add_subparsers(dest="servo_command", metavar="SERVO_COMMAND", required=True)
    ports = commands.add_parser("list-ports", help="list the serial ports of this machine")
    ports.add_argument("--json", action="store_true", help="print JSON")
    ports.set_defaults(handler=run_list_ports)
    move = commands.add_parser("move", help="arm, move to a pose at the joints' speeds, disarm")
    _link_options(move)
    move.add_argument("pose", nargs="+", metavar="JOINT=ANGLE", help="e.g. shoulder=40 elbow=30")
    move.set_defaults(handler=run_move)
    home = commands.add_parser("home", help="arm, move every joint to its home angle, disarm")
    _link_options(home)
    home.set_defaults(handler=run_move, pose=None)
    query = commands.add_parser("query", help="read each joint's angle from the controller")
    _link_options(query)
    query.set_defaults(handler=run_query)

    emulate = subparsers.add_parser("emulate-servo")
    emulate.add_argument(
        "--protocol", choices=sorted(PROTOCOLS), default="maestro", help="the controller to emulate"
    )
    emulate.add_argument("--link", help="also make this path a symlink to the port (a stable name)")
    emulate.add_argument(
        "--seconds",
        type=finite_float(0.0, MAX_EMULATE_S),
        help="stop after this many seconds (default: Ctrl-C)",
    )
    emulate.set_defaults(handler=run_emulate)


def _link_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--settings", help="settings file (default: the config dir's settings.json)"
    )
    parser.add_argument(
        "--port", help="serial port of the servo controller (default: from settings)"
    )
    parser.add_argument(
        "--protocol", help=f"one of {', '.join(PROTOCOLS)} (default: from settings)"
    )
    parser.add_argument(
        "--dry-run", action="store_true", help="send nothing: print the bytes instead"
    )
    parser.add_argument(
        "--timeout",
        type=finite_float(0.01, MAX_TIMEOUT_S),
        default=0.5,
        help="seconds to wait for an answer",
    )
    parser.add_argument("--json", action="store_true", help="print JSON")


def _open_link(args: argparse.Namespace, settings: Settings, out: TextIO) -> ServoLink:
    options: dict = {"timeout": args.timeout}
    if args.dry_run:
        clock = ManualClock()
        protocol = args.protocol or settings.protocol
        options |= {
            "dry_run": True,
            "clock": clock,
            "sleep": clock.sleep,
            "on_bytes": lambda data: write_line(f"  bytes: {_show_bytes(protocol, data)}", out),
        }
    return ServoLink.open(
        args.port or settings.serial_port,
        args.protocol or settings.protocol,
        settings.joints,
        **options,
    )


def _show_bytes(protocol: str, data: bytes) -> str:
    if protocol == "ssc32":
        return repr(data.decode("ascii", "replace"))
    return data.hex(" ")


def _angles(pose: dict[str, float]) -> str:
    """Whole degrees, as the paper's transcript shows them; a one-joint pose is just its number."""
    if len(pose) == 1:
        return f"{next(iter(pose.values())):.0f}"
    return " ".join(f"{name}={angle:.0f}" for name, angle in pose.items())


def parse_pose(text: str, default_joint: str) -> dict[str, float]:
    """`42` (the default joint) or `shoulder=40 elbow=30` (commas also separate)."""
    words = [w for w in re.split(r"[\s,]+", text.strip()) if w]
    if not words:
        raise ServantError("no action given; type an angle, or joint=angle pairs")
    bare = len(words) == 1 and "=" not in words[0]
    pose: dict[str, float] = {}
    for word in words:
        name, sep, value = (default_joint, "=", word) if bare else word.partition("=")
        try:
            angle = float(value)
        except ValueError:
            angle = math.nan
        if not sep or not math.isfinite(angle):
            raise ServantError(f"{word!r} is not an angle; type a number, or joint=angle pairs")
        pose[name] = angle
    return pose


# -- servo ---------------------------------------------------------------------------------


def run_list_ports(args: argparse.Namespace) -> int:
    from serial.tools import list_ports

    ports = [{"port": p.device, "description": p.description} for p in list_ports.comports()]
    ports += announced_ports()  # the emulators' pseudo-terminals, which comports never lists
    text = "\n".join(f"{p['port']}\t{p['description']}" for p in ports) or (
        "No serial ports found. Without hardware, `servant emulate-servo` "
        "starts an emulated controller."
    )
    emit(args, ports, text)
    return 0


def run_move(args: argparse.Namespace) -> int:
    settings = load_settings(args.settings)
    out = sys.stderr if args.json else sys.stdout
    with _open_link(args, settings, out) as link:
        pose = (
            parse_pose(" ".join(args.pose), settings.joints[0].name)
            if args.pose
            else {j.name: j.home_angle for j in settings.joints}
        )
        link.arm()
        reached = link.move_to(pose)
        for note in link.notes:
            write_line(terminal_text(note), out)
        emit(
            args,
            {
                "pose": reached,
                "clamped": link.notes,
                "controller": link.controller,
                "port": link.port,
            },
            f"moved to {pose_text(reached)}",
        )
    return 0


def run_query(args: argparse.Namespace) -> int:
    settings = load_settings(args.settings)
    with _open_link(args, settings, sys.stderr if args.json else sys.stdout) as link:
        angles = link.read_positions()
    text = (
        "\n".join(f"{name}\t{angle:.1f}" for name, angle in angles.items())
        or "no joint sends a pulse yet"
    )
    emit(args, {"angles": angles, "port": link.port, "controller": link.controller}, text)
    return 0


def run_emulate(args: argparse.Namespace) -> int:
    emulator, port = start_emulator(args.protocol, link=args.link)
    try:
        joints = load_settings().joints
    except ServantError:  # the user's settings only name the channels here; they may be broken
        joints = Settings().joints
    stop = threading.Event()
    watcher = threading.Thread(
        target=_say_moves, args=(emulator, joints, stop), name="emulator-moves", daemon=True
    )
    watcher.start()
    withdraw = announce(
        port, f"Servant's emulated {PROTOCOLS[args.protocol].title} (servant emulate-servo)"
    )

    def stop_serving() -> None:
        withdraw()
        stop.set()
        watcher.join()
        emulator.stop()

    return serve_until_stopped(
        stop_serving,
        f"Emulating a {PROTOCOLS[args.protocol].title} on {port}; connect with "
        f"`servant servo query --port {port} --protocol {args.protocol}`. Ctrl-C stops.",
        args.seconds,
    )


MOVE_QUIET_S = 0.3  # a rate-limited move is many small targets; one line once they stop coming


def _say_moves(emulator: ServoEmulator, joints: list[Joint], stop: threading.Event) -> None:
    """One line per move the emulator receives: each channel's last target, once the targets
    have stopped coming for `MOVE_QUIET_S` (the link steps a move at 50 Hz)."""
    newest = -math.inf
    pending: dict[int, float] = {}
    while not stop.wait(0.1):
        for t, channel, value in emulator.history():
            if t > newest:
                newest, pending[channel] = t, value
        if pending and emulator.clock() - newest >= MOVE_QUIET_S:
            text = _targets_text(emulator, joints, pending)  # joint names from the settings
            print(terminal_text(f"received a move: {text}"), flush=True)
            pending = {}


def _targets_text(emulator: ServoEmulator, joints: list[Joint], targets: dict[int, float]) -> str:
    """`shoulder 40° (channel 0, 1500 µs)`: the joint of the settings on that channel, if any.
    StandardFirmata takes an angle below 544 and a pulse width from there."""
    by_channel = {j.channel: j for j in joints}
    words = []
    for channel, value in sorted(targets.items()):
        joint = by_channel.get(channel)
        if emulator.protocol == "firmata" and value < 544:
            words.append(f"channel {channel} {value:.0f}° (servo angle)")
        elif joint is None:
            words.append(f"channel {channel} {value:.0f} µs")
        else:
            angle = pulse_to_angle(joint, value)
            words.append(f"{joint.name} {round(angle):d}° (channel {channel}, {value:.0f} µs)")
    return ", ".join(words)


# -- teach ---------------------------------------------------------------------------------


MAX_ANSWER_CHARS = 1000  # a scene's label or a command in a teach session, and far more


class Session:
    """Prompts on `out`, answers from `inp`; when input is not a terminal, answers are echoed so
    a scripted session's transcript reads like an interactive one."""

    def __init__(self, inp: TextIO, out: TextIO) -> None:
        self.inp, self.out = inp, out
        self.echo = not (hasattr(inp, "isatty") and inp.isatty())

    def say(self, line: str) -> None:
        write_line(terminal_text(line), self.out)

    def ask(self, prompt: str) -> str | None:
        """The answer, stripped; None at the end of input. An answer is a scene's label or an
        angle: one longer than `MAX_ANSWER_CHARS` is refused, not read to its end (`teach <
        /dev/zero` read one endless line until memory ran out)."""
        self.out.write(prompt)
        self.out.flush()
        line = self.inp.readline(MAX_ANSWER_CHARS + 1)
        if len(line.rstrip("\n")) > MAX_ANSWER_CHARS:
            raise ServantError(
                f"teach: an answer longer than {MAX_ANSWER_CHARS} characters; a scene's label "
                "or an angle is short: check what is given to teach on its input"
            )
        if not line:
            if self.echo:
                self.out.write("\n")
            return None
        if self.echo:
            self.out.write(terminal_text(line if line.endswith("\n") else line + "\n"))
        return line.strip()


def run_teach(
    args: argparse.Namespace, inp: TextIO | None = None, out: TextIO | None = None
) -> int:
    inp = inp or sys.stdin
    if inp is None:  # started with stdin closed (`servant teach <&-`)
        raise ServantError(
            "teach reads the session from stdin, which is closed; run it in a terminal"
        )
    session = Session(inp, out or sys.stdout)
    settings = load_settings(args.settings)
    joint = settings.joint(args.joint).name if args.joint else settings.joints[0].name
    records_path = args.records or default_records_path()
    learner_path = args.learner or default_learner_path()
    if not args.predict_only:  # before the session, not after what was taught in it
        check_records_output(records_path)
        check_learner_output(learner_path)
    link = _open_link(args, settings, session.out) if (args.port or args.dry_run) else None
    try:
        if link is not None:
            link.arm()
            session.say(
                f"The arm is armed on {link.port} ({link.protocol.title}); it moves as you teach."
            )
        if args.predict_only:
            learner = ActionLearner.load(learner_path)
        else:
            learner = _train(args, settings, session, joint, records_path, link)
            learner.save(learner_path)
        _predict(learner, session, link)
    finally:
        if link is not None:
            link.close()
    return 0


def _train(
    args: argparse.Namespace,
    settings: Settings,
    session: Session,
    joint: str,
    records_path: str | Path,
    link: ServoLink | None,
) -> ActionLearner:
    joints = {j.name: j for j in settings.joints}
    records = load_records(records_path, legacy_joint=joint)
    if records:
        session.say(f"Loaded {len(records)} earlier teach records from {records_path}.")
    session.say(
        f"Training phase. Type a scene label, then the action: an angle for {joint}, "
        "joint=angle pairs"
        + (", or `record [seconds]` to read the pose you guide the arm into" if link else "")
        + ". An empty label ends training."
    )
    while (label := _ask_label(session, records)) is not None:
        answer = _ask_pose(session, joint, joints, link)
        if answer is None:
            session.say(f"No action for {label}; nothing recorded.")
            continue
        pose, source, notes = answer
        record = TeachRecord(label, label_scores(label), pose, time.time(), source, notes)
        records = append_record(record, records_path, legacy_joint=joint)
        if link is not None and link.armed:
            _act(link, pose, session.say)
    if not records:  # the input ended (or an empty label came) before any scene was taught
        raise ServantError(
            "nothing to learn from: teach at least one scene (a label, then its action), "
            "or ask a learner taught before with --predict-only"
        )
    session.say(f"Learning from {len(records)} teach records...")
    learner = ActionLearner(
        max_iter=args.iterations,
        confidence_threshold=settings.confidence_threshold,
        home={j.name: j.home_angle for j in settings.joints},
    )

    def report(iterations: int, error: float) -> None:
        unit = "iteration" if iterations == 1 else "iterations"
        session.say(f"Error after {iterations} {unit}: {error:.4f} degrees")

    return learner.fit(records, report=report)


def _ask_label(session: Session, records: list[TeachRecord]) -> str | None:
    """The next place's label by the rule for places' names (`place_names`), asked again until
    it is one; a place already taught in another case is that place. None when labels end."""
    while label := session.ask("Scene label: "):
        try:
            return place_name(label, known=[r.scene for r in records])
        except ServantError as error:
            session.say(str(error))
    return None


def _ask_pose(
    session: Session, joint: str, joints: dict[str, Joint], link: ServoLink | None
) -> tuple[dict[str, float], str, list[str]] | None:
    """Ask until the action is a pose the arm can take (clamped, said so); None at end of input."""
    while (answer := session.ask("What action should I take? ")) is not None:
        try:
            if answer.split()[:1] == ["record"]:
                return _record_pose(session, answer, link)
            pose, notes = clamp_pose(joints, parse_pose(answer, joint))
        except ServantError as error:
            session.say(str(error))
            continue
        for note in notes:
            session.say(note)
        return pose, "typed", notes
    return None


def _record_pose(
    session: Session, answer: str, link: ServoLink | None
) -> tuple[dict[str, float], str, list[str]]:
    if link is None:
        raise ServantError("recording reads the arm's positions: start `servant teach` with --port")
    words = answer.split()
    try:
        duration = float(words[1]) if len(words) > 1 else RECORD_SECONDS
    except ValueError:
        raise ServantError(f"{words[1]!r} is not a number of seconds") from None
    duration = seconds(duration, "a recording", MAX_RECORD_S, zero=True)  # before disarming
    link.disarm()  # the user guides the arm: it must not fight back
    session.say(f"Recording for {duration:g} s: guide the arm into the pose.")
    samples = link.record(duration)
    if not samples[-1]:
        raise ServantError("the controller reported no joint positions; move the arm and try again")
    pose, notes = clamp_pose(link.joints, samples[-1])
    session.say(f"Recorded {_angles(pose)}.")
    link.arm()
    return pose, "recorded", notes


def _predict(learner: ActionLearner, session: Session, link: ServoLink | None) -> None:
    session.say("Prediction phase. Type a scene label; an empty line ends.")
    while label := session.ask("Tell me something: "):
        # a place taught as `cafe` is the place asked about as `Cafe`, as when it is taught
        label = next((s for s in learner.scenes_ if place_key(s) == place_key(label)), label)
        # A typed label is certain: confidence 100 %, one-hot scores.
        prediction = learner.predict(label_scores(label, learner.scenes_), label, 100.0)
        if prediction.pose is None:
            session.say(prediction.reason or "")
            continue
        session.say(_angles(prediction.pose))
        if link is not None:
            _act(link, prediction.pose, session.say)


def _act(link: ServoLink, pose: dict[str, float], say: Callable[[str], None]) -> None:
    try:
        link.move_to(pose)
        for note in link.notes:
            say(note)
    except ServantError as error:
        say(str(error))
