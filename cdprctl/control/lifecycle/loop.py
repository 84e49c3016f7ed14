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
        self.deadline = np.zeros(size)  # s, monotonic clock: each cycle's deadline
        self.lateness = np.zeros(size)  # s, wake-up after the deadline
        self.compute = np.zeros(size)  # s, step duration (the controller's)
        self.phases = np.zeros((size, phases))  # µs per phase (from the controller)
        self.count = 0
        self.overruns = 0  # steps longer than a period
        self.missed = 0  # periods skipped

    def record(
        self,
        late: float,
        compute: float,
        phases: np.ndarray | None,
        deadline: float = math.nan,
    ) -> None:
        i = self.count % self.size
        self.deadline[i] = deadline
        self.lateness[i] = late
        self.compute[i] = compute
        if phases is not None:
            self.phases[i] = phases
        self.count += 1

    def save(self, path: str, period: float) -> None:
        """The recorded cycles, oldest first, to ``path`` (numpy ``.npz``): ``deadline`` (s,
        monotonic clock), ``lateness`` and ``compute`` (s), ``phases`` (µs, the
        controller's), ``period`` (s), and the totals ``overruns`` and ``missed``."""
        n = min(self.count, self.size)
        order = np.arange(self.count - n, self.count) % self.size
        np.savez(
            path,
            deadline=self.deadline[order],
            lateness=self.lateness[order],
            compute=self.compute[order],
            phases=self.phases[order],
            period=period,
            overruns=self.overruns,
            missed=self.missed,
        )

    def summary(self, last: int | None = None) -> dict[str, float]:
        """Totals (cycles, overruns, missed) and the percentiles of wake lateness and compute
        (µs) over the whole ring, or over the ``last`` cycles: what the daemon's I/O thread
        reports while the loop runs (a percentile of the whole ring holds the GIL ~10 ms and
        delays the loop's wake-up)."""
        n = min(self.count, self.size, self.size if last is None else max(1, last))
        if self.count == 0:
            return {"cycles": 0}
        idx = np.arange(self.count - n, self.count) % self.size
        late = self.lateness[idx] * 1e6
        comp = self.compute[idx] * 1e6
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


def periods_missed(late: float, period: float) -> int:
    """The periods a cycle ``late`` s behind its deadline skips: every whole one missed once
    it is more than a period late, so that a stall is never followed by a burst of catch-up
    cycles (their SYNCs bunched, the drives' targets a step). The daemon's loop and the
    calibration's cycles (``calibration.session``) both."""
    return math.floor(late / period) if late > period else 0


def run_loop(
    period: float,
    step: Callable[[float], None],
    should_stop: Callable[[], bool],
    sleep_margin: float = 0.0002,
    stats: LoopStats | None = None,
    phases: Callable[[], np.ndarray] | None = None,
    clock: Callable[[], float] = time.monotonic,
    after: Callable[[], None] | None = None,
) -> LoopStats:
    """Call ``step(t)`` every ``period`` seconds until ``should_stop()``; ``after()`` at the
    end of each cycle (the daemon's I/O thread works in the idle rest of the period)."""
    st = stats or LoopStats()
    deadline = clock() + period
    while not should_stop():
        now = clock()
        wait = deadline - now - sleep_margin
        if wait > 0:
            time.sleep(wait)
        while (now := clock()) < deadline:
            pass
        skipped = periods_missed(now - deadline, period)
        st.missed += skipped
        deadline += skipped * period
        late = now - deadline
        # the cycle's time is when it runs, not its deadline: a late cycle's position targets
        # are for the instant its SYNC goes out (for its deadline, up to a period behind,
        # the drives reversed out of their extrapolation and faulted on their following error
        # across processes on a loaded machine)
        step(now)
        compute = clock() - now
        if compute > period:
            st.overruns += 1
        st.record(late, compute, phases() if phases is not None else None, deadline)
        if after is not None:
            after()
        deadline += period
    return st
