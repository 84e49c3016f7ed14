"""Real-time settings of the loop's process, where permitted, with a clear warning where not."""

from __future__ import annotations

import ctypes
import ctypes.util
import gc
import os

MCL_CURRENT, MCL_FUTURE = 1, 2


def apply_realtime(priority: int, cpu: int, lock_memory: bool, freeze_gc: bool) -> list[str]:
    """SCHED_FIFO at ``priority``, pinned to ``cpu`` (-1: the last), memory locked, the
    garbage collector frozen. Returns one warning per setting that could not be applied."""
    warnings: list[str] = []
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError, AttributeError) as exc:
        warnings.append(
            f"SCHED_FIFO priority {priority} not permitted ({exc}): the loop runs with the "
            "normal scheduler and its timer slack; grant CAP_SYS_NICE or LimitRTPRIO "
            "(systemd/cdprctl.service)"
        )
    try:
        cpus = sorted(os.sched_getaffinity(0))
        target = cpus[-1] if cpu < 0 else cpu
        os.sched_setaffinity(0, {target})
    except (OSError, AttributeError, ValueError) as exc:
        warnings.append(f"CPU affinity to CPU {cpu} not applied ({exc})")
    if lock_memory:
        libc_name = ctypes.util.find_library("c")
        ok = False
        if libc_name:
            libc = ctypes.CDLL(libc_name, use_errno=True)
            ok = libc.mlockall(MCL_CURRENT | MCL_FUTURE) == 0
        if not ok:
            warnings.append(
                "mlockall refused: pages may be swapped out under memory pressure; "
                "grant CAP_IPC_LOCK or LimitMEMLOCK=infinity"
            )
    if freeze_gc:
        gc.collect()
        gc.freeze()  # what exists now is never scanned again
        gc.disable()  # no cyclic collection pauses in the loop (reference counting still frees)
    return warnings


def loop_cpu(cpu: int) -> int | None:
    """The CPU the loop is pinned to (``cpu``, -1: the last one allowed); None if unknown."""
    try:
        cpus = sorted(os.sched_getaffinity(0))
    except (OSError, AttributeError):
        return None
    return cpus[-1] if cpu < 0 else cpu


def yield_to_the_loop(loop_cpu_index: int | None, niceness: int = 10) -> list[str]:
    """For a helper process (the Zenoh gateway): run at a lower priority and, when there is
    another CPU, away from the loop's, so the helper's bursts (a command flood) never take the
    loop's CPU. Returns warnings for what could not be applied."""
    warnings: list[str] = []
    try:
        os.nice(niceness)
    except OSError as exc:
        warnings.append(f"nice {niceness} not applied ({exc})")
    try:
        cpus = set(os.sched_getaffinity(0))
        others = cpus - {loop_cpu_index}
        if loop_cpu_index is not None and others:
            os.sched_setaffinity(0, others)
    except (OSError, AttributeError) as exc:
        warnings.append(f"CPU affinity away from the loop's CPU not applied ({exc})")
    return warnings


def restore_gc() -> None:
    gc.enable()
    gc.unfreeze()
