"""The CiA 402 SYNC's timing: when the control loop may send one, the instants of the last
ones (each TPDO1 is stamped at the instant of the SYNC it answers), the counter it carries, and
when a cycle's position targets went out so long before their SYNC that they must go out again.

One object owns that state (``Cia402Driver.sync``); the compiled decode reads its arrays
(``instants``, ``answered``, ``rate``) through ``sync_instant``. Plain arithmetic on the clock's
readings: no bus, no drive.
"""

from __future__ import annotations

import math

import can
import numpy as np

from cdprctl.core.numerics import cycle_kernel
from drivers.cia402 import protocol as p

# counts: a SYNC fits a late TPDO1 better than the sequence's only by more than this (the
# encoder's quantisation and a period's change of rate at rest are below it)
SYNC_FIT_COUNTS = 4.0


class SyncClock:
    """The SYNCs a driver sent and the rules of sending the next one."""

    RING = 8  # SYNC instants kept
    LAG_MAX = 4  # SYNCs a late TPDO1 may answer behind the newest (``sync_instant``)
    # of a period: targets this much older than their SYNC are sent again
    RESEND_AFTER = 0.25
    # times the targets may go out again before one SYNC (each check costs a clock read)
    RESEND_TRIES = 3

    def __init__(self, m: int, period: float, n_buses: int):
        """``m`` drives, the control ``period`` (s), ``n_buses`` buses of the config."""
        self.period = period
        # the SYNCs' instants by sequence number (a ring), the newest's number, and the one
        # each drive's last TPDO1 answered: each frame is stamped at its own SYNC's instant
        self.instants = np.full(self.RING, math.nan)
        self.seqs = np.zeros(1, dtype=np.int64)  # [the newest's number] (in place: no int)
        self.answered = np.zeros(m, dtype=np.int64)
        self.rate = np.zeros(m)  # counts/s: each drive's last step over its time
        self.last = math.nan  # s (clock): the last SYNC sent (nan: none yet)
        self.of_write = math.nan  # s (clock): the last write's SYNC (nan: it sent none)
        self.last_cycle = -math.inf  # s (clock): the last one the control loop sent
        self.frame = can.Message(arbitration_id=p.SYNC, data=bytearray(1), is_extended_id=False)
        self.plain = can.Message(arbitration_id=p.SYNC, data=b"", is_extended_id=False)
        # per bus: its medium's SYNC carries the counter (every drive there has 0x1019)
        self.counted = [True] * n_buses

    def begin_write(self) -> None:
        """A write starts: it has sent no SYNC yet."""
        self.of_write = math.nan

    def due(self, now: float, setup: bool) -> bool:
        """Whether a write at ``now`` (s, clock) sends its SYNC. The SYNC is the drives' time
        base: the control loop never sends two within half a period (on the clock: a late
        cycle's time is not when it sends). A late cycle followed at once by the next one (a
        loaded machine) sent SYNCs 0 ms apart, then none for 16 ms: the drives' interpolation
        overshot and faulted on its following error (across processes, 2 busy loops on 2
        cores). Its RPDOs wait for the next. The set-up's own cycling (``setup``) always
        sends one."""
        return setup or now - self.last_cycle >= 0.5 * self.period

    def behind(self, late: float, again: float, after: float) -> bool:
        """Whether targets carried ``late`` s on, now ``again`` s after their cycle's start,
        are more than ``after`` of a period behind their SYNC: sent again."""
        return again - late > after * self.period

    def advance(self) -> None:
        """The counter of the SYNC about to go out (1 … ``SYNC_COUNTER_OVERFLOW``): in
        ``frame``, which goes to the buses whose drives all count (``counted``); the others
        get ``plain``."""
        data = self.frame.data
        data[0] = data[0] % p.SYNC_COUNTER_OVERFLOW + 1

    def sent(self, now: float, setup: bool) -> None:
        """A SYNC went out at ``now`` (s, clock), of the set-up's cycling if ``setup``."""
        self.last = self.of_write = now
        sync_sent_kernel(self.seqs, self.instants, now)
        if not setup:
            self.last_cycle = now

    @property
    def seq(self) -> int:
        """The newest SYNC's sequence number (0: none yet)."""
        return int(self.seqs[0])

    def sent_instant(self, now: float) -> float:
        """When the drives take the last write's frames: its SYNC, when it sent one, else
        ``now``."""
        s = self.of_write
        return s if math.isfinite(s) else now


@cycle_kernel
def sync_sent_kernel(seqs, instants, now):  # pragma: no cover - compiled
    """The next sequence number into ``seqs[0]``, its instant ``now`` (s) into the ring."""
    seqs[0] += 1
    instants[seqs[0] % instants.shape[0]] = now


@cycle_kernel
def sync_instant(c, pos, syncs, seq, answered, lag_max, raw, fb_stamp, rate, fallback):
    """The instant (s) of the SYNC a TPDO1 of cable ``c`` (32-bit position ``pos``) answers.
    Transmission type 1: one TPDO1 per SYNC, so a drive's next answer is to the SYNC after the
    one it last answered (``answered[c]``, a sequence number; ``syncs``: the instants of the
    last SYNCs, a ring by sequence number, ``seq`` the newest) — unless an answer was lost.
    So every SYNC since the one it answered (at most ``lag_max`` back) is a candidate, and
    the one whose instant fits the drive's last rate best wins (``rate``, counts/s, since its
    last sample ``raw[c, 0]`` at ``fb_stamp[c]``) where it fits better than the sequence's
    by more than ``SYNC_FIT_COUNTS``; at rest they fit alike and the sequence decides, where
    a wrong instant costs nothing. An answer later than ``lag_max`` SYNCs is taken as of the
    oldest candidate. Stamped at its arrival's SYNC instead, an
    answer late on a busy bus read a period fresher than it was: the forward kinematics mixed
    two instants (a 5 mm residual fault across processes beside two busy processes).
    ``fallback`` (s) before the first SYNC."""
    if seq <= 0:
        return fallback
    # never a SYNC it answered already: after a stall the drive's rate says nothing of when
    lo = min(max(answered[c] + 1, seq - lag_max, seq - len(syncs) + 1, 1), seq)
    chosen = lo
    if lo < seq and raw[c, 1] != 0 and np.isfinite(fb_stamp[c]):
        step = ((pos - raw[c, 0] + 0x80000000) & 0xFFFFFFFF) - 0x80000000
        ring = len(syncs)
        err_chosen = abs(step - rate[c] * (syncs[chosen % ring] - fb_stamp[c]))
        best, err_best = chosen, err_chosen
        for a in range(lo, seq + 1):
            err = abs(step - rate[c] * (syncs[a % ring] - fb_stamp[c]))
            if err < err_best:
                err_best, best = err, a
        if err_chosen - err_best > SYNC_FIT_COUNTS:
            chosen = best
    answered[c] = chosen
    return syncs[chosen % len(syncs)]
