"""Fuzz (issue 13): whatever bytes come back from a servo controller, the link reads positions or
says one clear ServantError, in bounded time, disarmed after any fault, and never commands a
joint beyond its limits.

Two levels: the protocols' reply parsers on random and mutated replies (pure functions, many
cases), and the whole link through pyserial on a fake port answering each request from a script
of random bytes, which may also vanish at any point (a controller unplugged).
"""

from __future__ import annotations

import functools
import math
import sys
import termios
import time
import types

import pytest
import serial
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from serial.urlhandler.protocol_loop import Serial as LoopSerial

from servant_core.errors import ServantError
from servant_core.servo import Move, ProtocolError, protocol_for
from servant_core.servo.emulator import ServoEmulator
from servant_core.servo.link import ManualClock, ServoLink
from servant_core.settings import default_joints

JOINTS = default_joints()
BY_CHANNEL = {j.channel: j for j in JOINTS}
PROTOCOLS = ["maestro", "ssc32", "firmata"]
# Script steps that unplug: after this write (the next call fails, as on a pty whose other side
# is gone), or during it.
GONE, FAIL = "gone", "fail"
WRITTEN: list[bytes] = []  # every byte the link wrote in the current case, in order


class ScriptedPort(LoopSerial):
    """`script://HEX/HEX/...`: the n-th write is answered with the n-th reply, then silence.

    A fake, because no controller sends arbitrary bytes on demand: pyserial's own loop:// port,
    with `write` answering from the script instead of echoing. After a `GONE` or `FAIL` step
    every call raises what pyserial raises for a pty whose other side is gone.
    """

    def from_url(self, url: str) -> None:
        self.script = url.split("://", 1)[1].split("/")
        self.gone = False
        self.queue.maxsize = 0  # a controller may answer more than loop://'s 4 KiB

    def _check(self) -> None:
        if self.gone:
            raise termios.error(5, "Input/output error")

    def write(self, data: bytes) -> int:
        self._check()
        WRITTEN.append(bytes(data))
        step = self.script.pop(0) if self.script else ""
        if step in (GONE, FAIL):
            self.gone = True
            if step == FAIL:
                raise serial.SerialException("write failed: [Errno 5] Input/output error")
            return len(data)
        for byte in bytes.fromhex(step):
            self.queue.put_nowait(bytes((byte,)))
        return len(data)

    def read(self, size: int = 1) -> bytes:
        self._check()
        return super().read(size)

    def reset_input_buffer(self) -> None:
        self._check()
        super().reset_input_buffer()


# pyserial finds the class for `script://` as `Serial` in a module `protocol_script` of a package
# named in `serial.protocol_handler_packages`: this registers one without a file of its own.
_package = types.ModuleType("servant_fuzz_ports")
_package.__path__ = []  # type: ignore[attr-defined]
_handler = types.ModuleType("servant_fuzz_ports.protocol_script")
_handler.Serial = ScriptedPort  # type: ignore[attr-defined]
sys.modules.update({_package.__name__: _package, _handler.__name__: _handler})
if _package.__name__ not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append(_package.__name__)


@functools.cache
def valid_replies(protocol: str) -> tuple[bytes, bytes]:
    """What a healthy controller answers to the link's probe and position query."""
    emulator = ServoEmulator(protocol)
    proto = protocol_for(protocol)
    emulator.feed(proto.setup(JOINTS))
    emulator.feed(proto.move([Move(JOINTS[0].channel, JOINTS[0].min_pulse_us + 100)]))
    channels = [j.channel for j in JOINTS]  # the other joints send no pulse yet
    return emulator.feed(proto.probe()), emulator.feed(proto.query(channels))


@st.composite
def replies(draw: st.DrawFn, protocol: str) -> bytes:
    """Random bytes, or a real reply cut, stretched or with bytes changed."""
    if draw(st.booleans()):
        return draw(st.binary(max_size=300))
    reply = bytearray(draw(st.sampled_from(valid_replies(protocol))))
    for _ in range(draw(st.integers(0, 4))):
        where = draw(st.integers(0, len(reply)))
        kind = draw(st.sampled_from(["flip", "insert", "stretch", "cut", "repeat"]))
        if kind == "flip" and where < len(reply):
            reply[where] = draw(st.integers(0, 255))
        elif kind == "insert":
            reply[where:where] = draw(st.binary(min_size=1, max_size=200))
        elif kind == "stretch":  # data bytes only: a message that goes on and on
            reply[where:where] = bytes([draw(st.integers(1, 127))]) * draw(st.integers(1, 400))
        elif kind == "cut":
            del reply[where:]
        else:
            reply += bytes(reply)
    return bytes(reply)


@pytest.mark.parametrize("protocol", PROTOCOLS)
@settings(max_examples=300, deadline=None)
@given(data=st.data(), channels=st.lists(st.integers(0, 23), min_size=1, max_size=4))
def test_reply_parsers_accept_or_refuse_any_bytes(protocol, data, channels):
    reply = data.draw(replies(protocol))
    proto = protocol_for(protocol)
    joints = [j.channel for j in JOINTS]  # what the link asks; a reply may be for others
    for parse in (
        proto.parse_probe,
        lambda b: proto.parse_positions(b, joints),
        lambda b: proto.parse_positions(b, channels),
    ):
        try:
            result = parse(reply)
        except ProtocolError:
            continue
        if result is None:  # not complete yet
            continue
        value, used = result
        assert 0 < used <= len(reply)
        if isinstance(value, list):
            assert len(value) in (len(joints), len(channels))
            assert all(p is None or (math.isfinite(p) and p >= 0) for p in value)


scripts = st.lists(
    st.one_of(st.binary(max_size=60).map(bytes.hex), st.sampled_from([GONE, FAIL])),
    min_size=1,
    max_size=6,
)
poses = st.dictionaries(st.sampled_from([j.name for j in JOINTS]), st.floats(-400, 400))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(protocol=st.sampled_from(PROTOCOLS), script=scripts, pose=poses, valid=st.booleans())
def test_the_link_survives_any_reply_from_a_controller(protocol, script, pose, valid):
    if valid:  # a healthy probe answer first, so the fuzz reaches arming and moving
        script = [valid_replies(protocol)[0].hex(), "", *script]
    WRITTEN.clear()
    clock = ManualClock()
    started = time.monotonic()
    options = {"timeout": 0.05, "clock": clock, "sleep": clock.sleep}
    try:
        link = ServoLink.open("script://" + "/".join(script), protocol, JOINTS, **options)
    except ServantError as error:
        assert "\n" not in str(error)
        return
    with link:
        for action in (link.arm, lambda: link.move_to(pose, wait=False), link.read_positions):
            try:
                result = action()
            except ServantError as error:
                assert "\n" not in str(error)
                assert not link.armed
                continue
            assert all(math.isfinite(angle) for angle in result.values())
    assert time.monotonic() - started < 5.0
    decoder = ServoEmulator(protocol, clock=clock)
    decoder.feed(b"".join(WRITTEN))
    for _, channel, pulse in decoder.history():
        joint = BY_CHANNEL[channel]
        assert joint.min_pulse_us - 0.5 <= pulse <= joint.max_pulse_us + 0.5


def test_a_controller_that_never_stops_talking_is_cut_short():
    # Messages the link skips (Firmata analog reports), more than any reply: refused, not kept
    # until the deadline (a fast line would fill memory first).
    reports = bytes([0xE0, 0x01, 0x02]) * 3000
    script = [valid_replies("firmata")[0].hex(), "", reports.hex()]
    link = ServoLink.open("script://" + "/".join(script), "firmata", JOINTS, timeout=30.0)
    with link:
        started = time.monotonic()
        with pytest.raises(ServantError, match="bytes and still no complete reply"):
            link.read_positions()
        assert time.monotonic() - started < 10.0
