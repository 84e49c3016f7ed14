"""The real-time settings of the loop's process's other threads (cdprctl/core/realtime.py)."""

from __future__ import annotations

import os
import sys
import threading

import pytest

from cdprctl.core.realtime import LONG_WORK_NICE, SHORT_SWITCH, sharing_the_interpreter


def _in_a_thread(policy: int, priority: int) -> list[tuple[int, int, int, float]]:
    """(policy, priority, niceness, switch interval) before, inside and after
    sharing_the_interpreter, in a thread of its own started at ``policy``/``priority``."""
    seen: list[tuple[int, int, int, float]] = []

    def look() -> None:
        nice = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        seen.append((os.sched_getscheduler(0), os.sched_getparam(0).sched_priority, nice,
                     sys.getswitchinterval()))  # fmt: skip

    def body() -> None:
        os.sched_setscheduler(0, policy, os.sched_param(priority))
        look()
        with sharing_the_interpreter():
            look()
        look()

    t = threading.Thread(target=body)
    t.start()
    t.join()
    return seen


def _fifo_permitted() -> bool:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    except PermissionError:
        return False
    return True


def test_long_work_beside_the_loop_leaves_real_time_and_gets_its_priority_back():
    """A path planned in the I/O thread at FIFO spent its CPU's real-time budget: the kernel
    held the simulated robot there 52 ms, and the daemon stopped on its drives' silence."""
    if not _fifo_permitted():
        pytest.skip("SCHED_FIFO not permitted here")
    before, inside, after = _in_a_thread(os.SCHED_FIFO, 79)
    assert before[:2] == (os.SCHED_FIFO, 79)
    assert inside[:3] == (os.SCHED_OTHER, 0, LONG_WORK_NICE)
    assert inside[3] == pytest.approx(SHORT_SWITCH)
    assert after == before


def test_a_thread_at_the_normal_scheduler_stays_there():
    before, inside, after = _in_a_thread(os.SCHED_OTHER, 0)
    assert before[:2] == (os.SCHED_OTHER, 0) and inside[:3] == after[:3] == before[:3]
    assert inside[3] == pytest.approx(SHORT_SWITCH) and after == before
