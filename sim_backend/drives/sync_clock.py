"""A simulated drive's view of the SYNC (CiA 301 §7.2.5): the period it locks its interpolation
to, and whether the SYNC's counter (0x1019) says the RPDO waiting for it belongs to a SYNC the
drive missed."""

from __future__ import annotations

import math


class SyncClock:
    # SYNC intervals the period is the median of: a late SYNC or two at once do not move it, a
    # new rate (set-up to cycling) takes half the window
    WINDOW = 9

    def __init__(self, extrapolate_for: float):
        """``extrapolate_for`` (s): an interval this long or longer is a gap, not a period."""
        self.extrapolate_for = extrapolate_for
        self.last = -math.inf  # s, the last SYNC this drive saw
        self.count = 0  # the last SYNC's counter (0: none, or SYNCs without one)
        self.rpdos = 0  # RPDOs received since the last SYNC
        self.period = 0.0  # s, the drive's estimate (0: none yet)
        self._intervals: list[float] = []  # s, the last SYNC intervals

    def sync(self, t: float) -> float:
        """A SYNC at ``t`` (s): the interval since the last one (s), the period measured."""
        interval, self.last = t - self.last, t
        self._measure_period(interval)
        return interval

    def _measure_period(self, interval: float) -> None:
        """``period`` (s): the SYNC period as a drive locks to it, the median of the last
        ``WINDOW`` intervals. Interpolating over the last interval instead, SYNCs handled late
        by a loaded simulator (two in one step: an interval of 0) made a target step and a
        following-error fault mid-move."""
        if not 0.0 <= interval < self.extrapolate_for:
            return
        self._intervals.append(interval)
        del self._intervals[: -self.WINDOW]
        ordered = sorted(self._intervals)
        self.period = ordered[len(ordered) // 2]

    def missed_since_rpdo(self, data: bytes, overflow: int) -> bool:
        """Counts this SYNC (its ``data``; ``overflow``: 0x1019); True when its counter says
        SYNCs were lost since the last one and fewer RPDOs came than were sent (one before
        each SYNC): the pending one may be for a SYNC this drive missed. Applied now, its
        target is a period late: the drive falls behind by a period and its catch-up over the
        next lost SYNC overshoots (5 % frame loss, rowc: 0.37 rad, a following-error fault).
        One more RPDO than lost SYNCs: the last one came after them, for this SYNC."""
        received, self.rpdos = self.rpdos, 0
        if overflow < 2 or len(data) != 1:
            self.count = 0
            return False
        previous, self.count = self.count, data[0]
        missed = (self.count - previous - 1) % overflow if previous else 0
        return received <= missed
