"""What every method of ``cdprctl calibrate`` shares: its name in the lines it prints, and
its cycles held as the daemon's loop holds its own."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any


@contextlib.contextmanager
def moves_held(model: Any, realtime: bool, log: Callable[[str], None]) -> Iterator[None]:
    """A procedure's cycles as the daemon's loop runs its own: the garbage collector frozen
    (a full collection of what the start-up built held a cycle ~80 ms on this VM: the drives
    extrapolated, then a step in their targets) and, with ``realtime``, SCHED_FIFO on the
    loop's CPU (a late cycle is a tension spike on stiff cables: rowc's moves stopped short,
    a following error) and the CPUs kept awake (``[control.realtime] cpu_wakeup_latency``).
    Given back after."""
    from cdprctl.core import realtime as rt

    def warn(w: str) -> None:
        log(f"cdprctl calibrate: warning: {w}")

    try:
        for w in rt.lock_memory_and_freeze_gc(False, model.control.freeze_gc):
            warn(w)
        with rt.realtime_loop(model.control, realtime, warn):
            yield
    finally:
        rt.restore_gc()


WHO = "cdprctl calibrate"
