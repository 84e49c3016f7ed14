"""The systemd notification protocol (sd_notify(3)) and a watchdog that proves progress.

``notify("READY=1")`` sends a datagram to ``$NOTIFY_SOCKET`` (a path, or ``@name`` in the
abstract namespace); without the variable it does nothing. :class:`Watchdog` sends
``WATCHDOG=1`` every half ``WatchdogSec`` — only while the loop's cycle counter advances, so a
stuck loop gets the service restarted.
"""

from __future__ import annotations

import os
import socket
import threading
from collections.abc import Callable


def notify(message: str, env: dict[str, str] | None = None) -> bool:
    path = (env if env is not None else os.environ).get("NOTIFY_SOCKET")
    if not path:
        return False
    address = "\0" + path[1:] if path.startswith("@") else path
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC) as sock:
        try:
            sock.sendto(message.encode(), address)
        except OSError:
            return False
    return True


def watchdog_interval(env: dict[str, str] | None = None) -> float | None:
    """Half of ``WatchdogSec`` (s), from ``$WATCHDOG_USEC`` (for this process per
    ``$WATCHDOG_PID``), or None when the watchdog is off."""
    e = env if env is not None else os.environ
    usec = e.get("WATCHDOG_USEC")
    pid = e.get("WATCHDOG_PID")
    if not usec or (pid and int(pid) != os.getpid()):
        return None
    return int(usec) / 2e6


class Watchdog(threading.Thread):
    def __init__(
        self,
        counter: Callable[[], int],
        interval: float,
        send: Callable[[str], bool] = notify,
        on_start: Callable[[], None] | None = None,
    ):
        """``on_start()`` runs first in the thread (the daemon: leave the loop's CPU)."""
        super().__init__(name="sd-watchdog", daemon=True)
        self.on_start = on_start
        self.counter = counter
        self.interval = interval
        self.send = send
        self.stop_event = threading.Event()
        self.kicks = 0
        self.withheld = 0

    def run(self) -> None:
        if self.on_start is not None:
            self.on_start()
        last = self.counter()
        while not self.stop_event.wait(self.interval):
            now = self.counter()
            if now != last:
                self.send("WATCHDOG=1")
                self.kicks += 1
            else:
                self.withheld += 1  # the loop is stuck: let systemd notice
            last = now

    def stop(self) -> None:
        self.stop_event.set()
