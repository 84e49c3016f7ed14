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
    a following error). Given back after."""
    from cdprctl.core import realtime as rt
    from cdprctl.core.cpu_idle import CpuWakeupLatency

    awake = CpuWakeupLatency()
    try:
        for w in rt.lock_memory_and_freeze_gc(False, model.control.freeze_gc):
            log(f"cdprctl calibrate: warning: {w}")
        if realtime:
            for w in (*rt.schedule_realtime(model.control.sched_priority, model.control.cpu),
                      *awake.hold(model.control.cpu_wakeup_latency)):  # fmt: skip
                log(f"cdprctl calibrate: warning: {w}")
        yield
    finally:
        if realtime:
            rt.leave_realtime()
        awake.release()
        rt.restore_gc()


WHO = "cdprctl calibrate"
