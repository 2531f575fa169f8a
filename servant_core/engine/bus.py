"""The engine's outlet: subscribers, each device's latest status, and errors said once.

Subscribers are called on whichever thread emits (the sense thread, the arm's thread, or the one
calling `retrain`…): they must be quick and must not call back into the engine's `start`/`stop`.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from servant_core.events import DeviceStatus, ErrorEvent, Event

log = logging.getLogger(__name__)

Subscriber = Callable[[Event], None]


class EventBus:
    """Fans events out to subscribers; a subscriber that raises is logged, never fatal.

    `clock` stamps the statuses and errors it makes itself."""

    def __init__(self, clock: Callable[[], float]) -> None:
        self.clock = clock
        self._subscribers: list[Subscriber] = []
        self._lock = threading.Lock()
        self._status: dict[str, DeviceStatus] = {}
        self._reported_errors: set[str] = set()

    def subscribe(self, callback: Subscriber) -> Callable[[], None]:
        """Call `callback(event)` for every event from now on; returns the way to unsubscribe."""
        with self._lock:
            self._subscribers.append(callback)

        def unsubscribe() -> None:
            with self._lock:
                if callback in self._subscribers:
                    self._subscribers.remove(callback)

        return unsubscribe

    def emit(self, event: Event) -> None:
        with self._lock:
            subscribers = list(self._subscribers)
        for callback in subscribers:
            try:
                callback(event)
            except Exception:  # a broken subscriber must not stop the senses
                log.exception("event subscriber %r failed", callback)

    @property
    def status(self) -> dict[str, DeviceStatus]:
        """The latest status of each device ("microphone", "camera", "servo")."""
        return dict(self._status)

    def report(self, device: str, ok: bool, message: str) -> None:
        """Emit a DeviceStatus when a device's state changes: a fault is said once, however it then
        fails to reopen, until the device works again."""
        previous = self._status.get(device)
        if previous is not None and previous.ok == ok and (previous.message == message or not ok):
            return
        status = DeviceStatus(self.clock(), device, ok, message)
        self._status[device] = status
        self.emit(status)

    def forget(self, device: str) -> None:
        """The device was replaced (another one chosen in Settings): its next state is said,
        even a fault like the last one's."""
        self._status.pop(device, None)

    def error(self, message: str) -> None:
        """Emit an ErrorEvent the first time this message occurs."""
        if message in self._reported_errors:
            return
        self._reported_errors.add(message)
        self.emit(ErrorEvent(self.clock(), message))
