"""The fixed-rate loop: absolute deadlines on the monotonic clock, sleep then spin.

Each cycle waits until its deadline — ``time.sleep`` until ``sleep_margin`` before it, then a
busy wait (sleeping alone wakes ~110 µs late here; spinning the last 200 µs brings that to
~0.3 µs at the price of CPU) — records how late it woke, runs the step, and records the compute
time. A cycle that starts more than a period late skips the missed periods (counted), never
catches up in a burst. Statistics go to preallocated ring buffers.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np


class LoopStats:
    def __init__(self, size: int = 120_000, phases: int = 7):
        self.size = size
        self.lateness = np.zeros(size)  # s, wake-up after the deadline
        self.compute = np.zeros(size)  # s, step duration
        self.phases = np.zeros((size, phases))  # µs per phase (from the controller)
        self.count = 0
        self.overruns = 0  # steps longer than a period
        self.missed = 0  # periods skipped

    def record(self, late: float, compute: float, phases: np.ndarray | None) -> None:
        i = self.count % self.size
        self.lateness[i] = late
        self.compute[i] = compute
        if phases is not None:
            self.phases[i] = phases
        self.count += 1

    def summary(self) -> dict[str, float]:
        n = min(self.count, self.size)
        if n == 0:
            return {"cycles": 0}
        late = self.lateness[:n] * 1e6
        comp = self.compute[:n] * 1e6
        return {
            "cycles": float(self.count),
            "lateness_p50_us": float(np.percentile(late, 50)),
            "lateness_p99_us": float(np.percentile(late, 99)),
            "lateness_max_us": float(late.max()),
            "compute_p50_us": float(np.percentile(comp, 50)),
            "compute_p99_us": float(np.percentile(comp, 99)),
            "overruns": float(self.overruns),
            "missed": float(self.missed),
            "missed_percent": 100.0 * self.missed / max(1, self.count + self.missed),
        }


def run_loop(
    period: float,
    step: Callable[[float], None],
    should_stop: Callable[[], bool],
    sleep_margin: float = 0.0002,
    stats: LoopStats | None = None,
    phases: Callable[[], np.ndarray] | None = None,
    clock: Callable[[], float] = time.monotonic,
) -> LoopStats:
    """Call ``step(t)`` every ``period`` seconds until ``should_stop()``."""
    st = stats or LoopStats()
    deadline = clock() + period
    while not should_stop():
        now = clock()
        wait = deadline - now - sleep_margin
        if wait > 0:
            time.sleep(wait)
        while (now := clock()) < deadline:
            pass
        late = now - deadline
        if late > period:  # skip what was missed, no burst of catch-up cycles
            skipped = math.floor(late / period)
            st.missed += skipped
            deadline += skipped * period
            late = now - deadline
        step(deadline)
        compute = clock() - now
        if compute > period:
            st.overruns += 1
        st.record(late, compute, phases() if phases is not None else None)
        deadline += period
    return st
