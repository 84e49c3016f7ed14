"""Real-time settings of the loop's process, where permitted, with a clear warning where not."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import gc
import os
import sys
import threading
from collections.abc import Callable, Iterator
from typing import Any

MCL_CURRENT, MCL_FUTURE = 1, 2

try:  # the CPUs this process may use, before the loop's thread is pinned to one of them
    ALLOWED_CPUS = frozenset(os.sched_getaffinity(0))
except (OSError, AttributeError):
    ALLOWED_CPUS = frozenset()


def schedule_realtime(priority: int, cpu: int) -> list[str]:
    """The calling thread (the loop's) at SCHED_FIFO ``priority``, pinned to ``cpu`` (-1: the
    last). Right before the loop, after the start-up's work: a cold start compiles for a
    minute, and a FIFO task runs until it blocks — another real-time loop on that CPU then
    waited for it (benchmarks/bench_second_daemon.py: the running daemon faulted).
    Returns one warning per setting that could not be applied."""
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
    return warnings


@contextlib.contextmanager
def realtime_loop(control: Any, on: bool, warn: Callable[[str], None]) -> Iterator[None]:
    """The loop's real-time settings for the body of the ``with`` (the daemon's loop, a
    calibration's cycles), with ``on``: ``SCHED_FIFO`` and the CPU of ``control`` (the
    robot's ``[control]``: ``schedule_realtime``) and the CPUs kept awake
    (``cpu_wakeup_latency``: ``core/cpu_idle.py``), each refusal given to ``warn``; given
    back at its end, whatever ended it (the normal scheduler first: the shut-down's work
    comes after, and the CPUs' request released even if that failed)."""
    from cdprctl.core.cpu_idle import CpuWakeupLatency

    awake = CpuWakeupLatency()
    try:
        if on:
            for w in (*schedule_realtime(control.sched_priority, control.cpu),
                      *awake.hold(control.cpu_wakeup_latency)):  # fmt: skip
                warn(w)
        yield
    finally:
        try:
            if on:
                leave_realtime()
        finally:
            awake.release()


def leave_realtime() -> None:
    """The calling thread back at the normal scheduler, on every allowed CPU: after the loop,
    before the shut-down's work (the collector's first pass over the start-up's objects, the
    report) — at FIFO that work held another daemon's loop on the CPU for 1.3 s (measured
    beside a second daemon, benchmarks/bench_second_daemon.py)."""
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    if ALLOWED_CPUS:
        with contextlib.suppress(OSError, AttributeError):
            os.sched_setaffinity(0, ALLOWED_CPUS)


def lock_memory_and_freeze_gc(lock_memory: bool, freeze_gc: bool) -> list[str]:
    """Memory locked (``mlockall``), the garbage collector frozen: before the drives start
    (both take a while, and then the drives' heartbeats are watched). Returns one warning per
    setting that could not be applied."""
    warnings: list[str] = []
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
    if not ALLOWED_CPUS:
        return None
    return max(ALLOWED_CPUS) if cpu < 0 else cpu


def helper_thread(loop_cpu_index: int | None, loop_priority: int) -> None:
    """For the calling thread of the loop's process (the daemon's I/O thread, the watchdog):
    the CPUs but the loop's, and ``SCHED_FIFO`` one below the loop (the normal scheduler
    where that is refused). Threads inherit the loop's priority and CPU from the loop's
    thread, which starts them: a FIFO helper on the loop's CPU runs until it blocks, however
    late the loop's wake-up. And the helpers share the loop's GIL: a helper preempted by
    other work while it holds it (a command flood in the gateway, on the other CPU) stalls
    the loop, so it keeps a real-time priority. Best effort, silent: the loop's own settings
    were reported already."""
    _beside_the_loop(loop_cpu_index, max(1, loop_priority - 1))


#: the niceness of long work in the loop's process taken out of real time: ahead of the
#: machine's normal work (two busy processes at nice 0 get ~1 % of a CPU beside it), so it
#: seldom sits preempted while it holds the interpreter's lock the loop waits for
LONG_WORK_NICE = -20


def worker_thread(loop_cpu_index: int | None) -> None:
    """For a thread of the loop's process that starts and waits for long work while the loop
    holds the drives (the geometric calibration's identification, in a process of its own
    that inherits this thread's settings: ``core.child_compute``): the CPUs but the loop's,
    at the normal scheduler with nice ``LONG_WORK_NICE``. At ``SCHED_FIFO`` 1 (until
    2026-12-07, computing in this thread) its seconds of work spent its CPU's real-time
    budget (the kernel's ``sched_rt_runtime_us``, 950 ms a second), and the kernel then held
    every real-time task there — a simulated robot's too — for the rest of the second (its
    drives deaf; "stepped 156 ms late"); a copy of the loop's priority on its CPU would
    starve the loop. Best effort, silent."""
    tid = threading.get_native_id()
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    with contextlib.suppress(OSError, AttributeError):
        os.setpriority(os.PRIO_PROCESS, tid, LONG_WORK_NICE)
    _off_the_loops_cpu(loop_cpu_index)


def _beside_the_loop(loop_cpu_index: int | None, priority: int) -> None:
    """The calling thread at ``SCHED_FIFO`` ``priority`` (the normal scheduler where refused),
    on the CPUs but the loop's."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError):
        with contextlib.suppress(OSError, AttributeError):
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    _off_the_loops_cpu(loop_cpu_index)


def _off_the_loops_cpu(loop_cpu_index: int | None) -> None:
    """The calling thread on the CPUs but the loop's, where there is another (silent)."""
    others = ALLOWED_CPUS - {loop_cpu_index}
    if loop_cpu_index is not None and others:
        with contextlib.suppress(OSError, AttributeError):
            os.sched_setaffinity(0, others)


def simulator_realtime(loop_cpu_index: int | None, loop_priority: int) -> list[str]:
    """For the simulated robot's process (``cdprctl sim``), which stands for drives that have
    processors of their own: ``SCHED_FIFO`` one below the daemon's loop, so the machine's
    other work (two busy processes at normal priority) never holds it up, and the CPUs but
    the loop's where there is another, so it never holds the loop up either. Returns one
    warning per setting that could not be applied."""
    warnings: list[str] = []
    priority = max(1, loop_priority - 1)
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError, AttributeError) as exc:
        warnings.append(f"SCHED_FIFO priority {priority} not permitted ({exc}): the simulated "
                        "robot shares the CPU with the machine's other work and may be late; "
                        "it says so when it is")  # fmt: skip
    others = ALLOWED_CPUS - {loop_cpu_index}
    if loop_cpu_index is not None and others:
        try:
            os.sched_setaffinity(0, others)
        except (OSError, AttributeError) as exc:
            warnings.append(f"CPU affinity away from the loop's CPU not applied ({exc})")
    return warnings


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


#: s: the interpreter's switch interval while another thread works long beside the loop's
SHORT_SWITCH = 1e-4


@contextlib.contextmanager
def sharing_the_interpreter() -> Iterator[None]:
    """Around long Python work in a thread beside the loop's (``CommandDesk.submit``: a path
    or a resumed path planned in the I/O thread): the interpreter hands its lock to a waiting
    thread after ``SHORT_SWITCH`` instead of 5 ms, so the loop waits that long for it, not a
    period (rowc at 250 Hz: 14-17 periods missed within 1 s of a resume,
    benchmarks/bench_resume.py); and a ``SCHED_FIFO`` thread computes at the normal scheduler
    at nice ``LONG_WORK_NICE`` meanwhile, its own priority given back after. At the I/O
    thread's FIFO priority a path's plan spent its CPU's real-time budget (the kernel's
    ``sched_rt_runtime_us``, 950 ms a second), and the kernel then held every real-time task
    there, the simulated robot's too, for the rest of the second: its drives deaf 52 ms, the
    daemon stopped on their silence (README's ``run --sim --path``, every time)."""
    old = sys.getswitchinterval()
    sys.setswitchinterval(SHORT_SWITCH)
    own = _out_of_real_time()
    try:
        yield
    finally:
        sys.setswitchinterval(old)
        if own is not None:
            with contextlib.suppress(OSError):
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(own[0]))
                os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), own[1])


def _out_of_real_time() -> tuple[int, int] | None:
    """The calling thread, if at ``SCHED_FIFO``, at the normal scheduler with nice
    ``LONG_WORK_NICE``; returns its FIFO priority and niceness to give back, or None where
    nothing was changed (another policy, or refused)."""
    tid = threading.get_native_id()
    try:
        if os.sched_getscheduler(0) != os.SCHED_FIFO:
            return None
        own = (os.sched_getparam(0).sched_priority, os.getpriority(os.PRIO_PROCESS, tid))
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except (OSError, AttributeError):
        return None
    with contextlib.suppress(OSError):
        os.setpriority(os.PRIO_PROCESS, tid, LONG_WORK_NICE)
    return own


def restore_gc() -> None:
    gc.enable()
    gc.unfreeze()
