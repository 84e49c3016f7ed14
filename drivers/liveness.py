"""The liveness rules of drives on a fieldbus, per cable: the feedback's age, the reads that
missed it and their time, the heartbeat, and the plausibility of a position sample.

The protocol says when a cable's feedback arrived (``fresh[c] = True``, ``fb_stamp[c] = t``)
and when its heartbeat did (``last_hb[c] = t``); :meth:`Liveness.update` does the rest once a
cycle, compiled, and :meth:`Liveness.error` words the timeout of a cable past its limit.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from cdprctl.core.numerics import add_count, cycle_kernel, max2, min2, plausible_step_py
from drivers.errors import DriverError, DriverTimeoutError
from drivers.vocabulary import MISSED_FEEDBACK, DriverStats, WinchStates

#: m/s of cable: a position step faster than this between two samples is a corrupted frame
#: (or a failing encoder): five times the supervisor's speed limit
PLAUSIBLE_CABLE_SPEED = 5.0

#: s without a step of simulated drives after which a read's silence is theirs — a starved
#: simulator (they step every 0.5 ms), whose drives were deaf — not the drives' own
DRIVES_STALL = 0.005
#: s: a stall longer than this counts as silence again (a simulator hung, not starved: the
#: simulated robot catches up on at most 0.5 s, ``SimNetwork.MAX_CATCH_UP``)
DRIVES_STALL_LIMIT = 0.5


class Liveness:
    """Per-cable liveness state (arrays, written in place by the protocol and the kernel)."""

    def __init__(self, m: int, period: float, max_motor_speed: np.ndarray, stats: DriverStats,
                 feedback_timeout: float, heartbeat_timeout: float):  # fmt: skip
        """``period`` (s): the control period; ``max_motor_speed`` (rad/s per cable): the
        fastest a motor can turn (``PLAUSIBLE_CABLE_SPEED`` of cable); the timeouts (s) are
        the config's ``[drives] feedback_timeout`` and ``heartbeat_timeout``."""
        self.period = period
        self.stats = stats
        self.feedback_timeout = feedback_timeout
        self.heartbeat_timeout = heartbeat_timeout
        self.max_motor_speed = max_motor_speed
        self.fresh = np.zeros(m, dtype=bool)  # feedback arrived during this read
        self.fb_stamp = np.full(m, -math.inf)  # s, time of the last feedback
        self.missed = np.zeros(m, dtype=np.int64)  # consecutive reads without feedback
        # s of running cycles without feedback, per cable: each read adds the time since the
        # last one, at most two periods — a stall of the loop itself sends no SYNC, so the
        # drives could not answer; it is the loop's to report, not a drive's silence
        self.silent = np.zeros(m)
        self.last_hb = np.full(m, -math.inf)  # s, the drive's last heartbeat
        self.last_read = -math.inf
        self.started = False  # the drives were started: silence now counts
        # position samples no motor can make, in a row, per cable (a protocol may replace it
        # by a view of its own decoding state)
        self.implausible = np.zeros(m, dtype=np.int64)
        # s of the monotonic clock when simulated drives last stepped (a view of one float the
        # simulated robot's process writes), None for real drives: they have processors of
        # their own, and a simulator starved by a busy machine must not pass for a silent drive
        self.drives_ran_at: np.ndarray | None = None
        self.stalled_reads = np.zeros(1, dtype=np.int64)  # reads whose silence was excused
        self.stall = 0.0  # s: the simulated drives' stall at the last read (``drives_stall``)

    @classmethod
    def of_winches(cls, cables: Sequence[Any], period: float, stats: DriverStats,
                   config: Any) -> Liveness:  # fmt: skip
        """The liveness of ``cables``' drives (the model's: a winch each) at the control
        ``period`` (s), by ``config``'s (``[drives]``) timeouts. A position step faster than
        ``PLAUSIBLE_CABLE_SPEED`` of cable is a corrupted frame (or a failing encoder),
        dropped like a lost one: the liveness check then stops the robot if it persists."""
        r = np.array([w.winch.drum_radius / w.winch.gear_ratio for w in cables])
        return cls(len(cables), period, PLAUSIBLE_CABLE_SPEED / r, stats,
                   config.feedback_timeout, config.heartbeat_timeout)  # fmt: skip

    def plausible(self, c: int, step: float, stamp: float) -> bool:
        """Whether motor ``c`` can have turned by ``step`` (rad) since its last accepted
        sample, at ``stamp`` (s); counts the implausible ones."""
        prev = self.fb_stamp.item(c)  # item: a float, not a numpy scalar (a block)
        if not math.isfinite(prev):
            return True
        # a period of slack for timing jitter (the one rule: cdprctl.core.numerics.plausible_step)
        speed = self.max_motor_speed.item(c)
        if plausible_step_py(step, speed, stamp - prev, self.period):
            self.implausible[c] = 0
            return True
        self.implausible[c] += 1
        self.stats.implausible_frames += 1
        return False

    def read_gap(self, t: float) -> float:
        """s since the last read, at most two periods (0 at the same instant: that misses
        nothing; the first read: one period)."""
        gap = t - self.last_read if math.isfinite(self.last_read) else self.period
        self.last_read = t
        self.stall = self.drives_stall(t)  # once a read: the gap and the heartbeat's timeout
        if self.stall > 0.0:  # deaf, not silent: the simulator was not run
            add_count(self.stalled_reads, 0, 1)
            return 0.0
        return min2(max2(gap, 0.0), 2.0 * self.period)

    def drives_stall(self, t: float) -> float:
        """s simulated drives have not stepped for at ``t`` (s, monotonic) when that is more
        than ``DRIVES_STALL`` and at most ``DRIVES_STALL_LIMIT``: a stall ridden through (the
        heartbeat's timeout lengthened by it too); else, and always for real drives, 0."""
        ran = self.drives_ran_at
        if ran is None:
            return 0.0
        stall = t - ran.item(0)
        return stall if DRIVES_STALL < stall <= DRIVES_STALL_LIMIT else 0.0

    def update(self, t: float, gap: float, states: WinchStates) -> bool:
        """The cycle's bookkeeping (``liveness_kernel``) after the feedback was decoded, the
        ages into ``states``; True when a cable is past a limit (``error`` says which)."""
        missed, late = liveness_kernel(
            self.fresh, self.fb_stamp, self.missed, self.silent, self.last_hb, t, gap,
            self.started, self.feedback_timeout, self.heartbeat_timeout + self.stall,
            states.feedback_age, states.sampled_at,
        )  # fmt: skip
        if missed:
            add_count(self.stats.counts, MISSED_FEEDBACK, missed)
        return late

    def warm_up(self, states: WinchStates) -> None:
        """The kernel once, on copies (compiled or loaded before the drives start)."""
        liveness_kernel(
            self.fresh.copy(), self.fb_stamp.copy(), self.missed.copy(), self.silent.copy(),
            self.last_hb.copy(), 0.0, 0.002, True, self.feedback_timeout,
            self.heartbeat_timeout, states.feedback_age.copy(), states.sampled_at.copy(),
        )  # fmt: skip

    def _hung(self, t: float) -> str:
        """The words for simulated drives that have not stepped for a while at ``t``."""
        ran = self.drives_ran_at
        if ran is None or t - ran.item(0) <= DRIVES_STALL_LIMIT:
            return ""
        return (f" (the simulated robot has not stepped for {(t - ran.item(0)) * 1e3:.0f} ms: "
                f"its process hung, beyond the {DRIVES_STALL_LIMIT * 1e3:g} ms ridden through)")

    def error(self, c: int, t: float, where: str, feedback: str,
              age: float) -> DriverError | None:  # fmt: skip
        """The timeout error of cable ``c`` (``where``: its drive, in words; ``feedback``: what
        its feedback is called; ``age``: s since it) when a limit is passed
        (``feedback_timeout`` s without feedback, ``heartbeat_timeout`` s without heartbeat)."""
        if self.silent[c] > self.feedback_timeout:
            why = (
                f" (the last {int(self.implausible[c])} were position jumps no motor can "
                "make: corrupted frames or a failing encoder)"
                if self.implausible[c]
                else ""
            )
            return DriverTimeoutError(
                f"{where}: no {feedback} for {self.silent[c] * 1e3:.1f} ms "
                f"of running cycles ({int(self.missed[c])} reads, last {age * 1e3:.1f} ms ago; "
                f"feedback_timeout {self.feedback_timeout * 1e3:g} ms){why}{self._hung(t)}",
                c,
            )
        if (
            self.started
            and math.isfinite(self.last_hb[c])
            and t - self.last_hb[c] > self.heartbeat_timeout + self.stall
        ):
            return DriverTimeoutError(
                f"{where} lost: no heartbeat for {t - self.last_hb[c]:.3f} s "
                f"(timeout {self.heartbeat_timeout:g} s){self._hung(t)}",
                c,
            )
        return None


@cycle_kernel
def liveness_kernel(
    fresh, fb_stamp, missed, silent, last_hb, t, gap, started, fb_timeout, hb_timeout, age,
    sampled,
):  # pragma: no cover - compiled  # fmt: skip
    """Per cable: the count of consecutive reads without feedback and their time ``silent``
    (s; each read adds ``gap``, the capped time since the last read; silence counts once the
    drives were started and have spoken), the feedback age (s) and instant (``sampled``, s).
    Returns the cable-reads missed now and whether a cable was silent over ``fb_timeout`` s or
    ``hb_timeout`` s without heartbeat."""
    n_missed = 0
    late = False
    for c in range(len(fresh)):
        if fresh[c]:
            missed[c] = 0
            silent[c] = 0.0
        elif gap > 0.0 and started and np.isfinite(fb_stamp[c]):
            missed[c] += 1
            silent[c] += gap
            n_missed += 1
        age[c] = t - fb_stamp[c]
        sampled[c] = fb_stamp[c]
        if silent[c] > fb_timeout:
            late = True
        if started and np.isfinite(last_hb[c]) and t - last_hb[c] > hb_timeout:
            late = True
    return n_missed, late
