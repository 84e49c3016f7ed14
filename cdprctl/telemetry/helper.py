"""A helper process of the daemon (the Zenoh gateway, the Foxglove view), started with spawn.

It ignores SIGINT: a terminal's Ctrl-C goes to the whole process group, and the daemon stops
its helpers itself, through their stop event (each helper printed a ``KeyboardInterrupt``
traceback, two interleaved during a start-up). A helper that fails before it is ready says why
in one line, which the daemon prints at once instead of a traceback and a wait for a process
that had already died."""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable
from typing import Any


def helper_entry(target: Callable[..., None], failed: Any, *args: Any) -> None:
    """The process's target: ``target(*args)``; an exception goes to ``failed`` (a queue) as
    one line and ends the process with status 1."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        target(*args)
    except Exception as exc:
        text = " ".join(str(exc).split())  # one line
        failed.put(text if isinstance(exc, OSError) and text else f"{type(exc).__name__}: {text}")
        sys.exit(1)


def wait_ready(process: Any, ready: Any, failed: Any, timeout: float) -> str:
    """Wait until the helper sets ``ready``: "" then; else why not (its failure, or that it
    did not start within ``timeout`` s)."""
    deadline = time.monotonic() + timeout
    while not ready.wait(0.05):
        if not process.is_alive():
            reason = failed.get() if not failed.empty() else f"exit status {process.exitcode}"
            return reason
        if time.monotonic() > deadline:
            return f"it did not start in {timeout:g} s"
    return ""
