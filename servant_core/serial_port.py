"""Opening a serial port (pyserial), for the arm's controller and the sensor board alike, and
the errors a port that goes away raises. It lives below both device packages (`servo`,
`capture`) so that neither imports the other.
"""

from __future__ import annotations

import errno

import serial

from servant_core.errors import ServantError

POLL_S = 0.02  # how long one serial read waits before the link looks at its own deadline

try:
    import termios

    # pyserial lets termios.error (not an OSError) out of tcflush on a port whose device is gone.
    PORT_ERRORS: tuple[type[BaseException], ...] = (serial.SerialException, OSError, termios.error)
except ImportError:  # no termios on Windows
    PORT_ERRORS = (serial.SerialException, OSError)


def open_serial(port: str, baudrate: int) -> serial.SerialBase:
    """Open `port` exclusively, or say in one line why it cannot be opened.

    `port` is a device (/dev/ttyACM0, COM3) or a pyserial URL: `socket://host:port` reaches a
    controller behind a network bridge, `loop://` and handlers of one's own serve tests.
    """
    try:
        return serial.serial_for_url(
            port, baudrate, timeout=POLL_S, write_timeout=1.0, exclusive=True
        )
    except (serial.SerialException, OSError, ValueError) as exc:
        code = getattr(exc, "errno", None)
        text = str(exc)
        if code == errno.ENOENT or "No such file" in text:
            reason = "no such serial port; `servant servo list-ports` lists the ports there are"
        elif (
            code in (errno.EBUSY, errno.EAGAIN) or "lock" in text.lower() or "busy" in text.lower()
        ):
            reason = "the port is busy: another program has it open; close it and try again"
        elif code == errno.EACCES or "Permission denied" in text:
            reason = "permission denied; add yourself to the `dialout` group or fix the port's mode"
        elif code in (errno.ENOTTY, errno.EISDIR) or "Inappropriate ioctl" in text:
            reason = "not a serial port; `servant servo list-ports` lists the ports there are"
        else:
            reason = f"cannot open the port ({text})"
        raise ServantError(f"{port}: {reason}") from exc
