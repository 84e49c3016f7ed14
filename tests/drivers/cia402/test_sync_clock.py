"""The CiA 402 SYNC's timing on its own (``drivers/cia402/sync_clock.py``): no bus, no drive —
when the control loop may send a SYNC, the ring of the SYNCs' instants, the counter each one
carries and the plain SYNC of a medium without it, when targets are behind their SYNC, and the
instant a write's frames count as sent. (The instant a late TPDO1 answers:
tests/drivers/cia402/test_cia402_cyclic.py, ``sync_instant``.)"""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers.cia402 import protocol as p
from drivers.cia402.sync_clock import SyncClock

PERIOD = 0.004


def test_the_loop_never_sends_two_syncs_within_half_a_period():
    s = SyncClock(2, PERIOD, 1)
    assert s.due(0.0, setup=False)  # none sent yet
    s.sent(0.0, setup=False)
    assert not s.due(0.4 * PERIOD, setup=False)
    assert s.due(0.4 * PERIOD, setup=True)  # the set-up's cycling: always
    assert s.due(0.5 * PERIOD, setup=False)


def test_the_set_ups_syncs_do_not_hold_back_the_loops():
    s = SyncClock(2, PERIOD, 1)
    s.sent(1.0, setup=True)
    assert s.last == s.of_write == 1.0 and s.last_cycle == -math.inf
    assert s.due(1.0, setup=False)


def test_the_ring_holds_the_last_syncs_by_sequence_number():
    s = SyncClock(2, PERIOD, 1)
    for k in range(1, 12):
        s.sent(k * PERIOD, setup=False)
    assert s.seq == 11
    for k in range(11 - SyncClock.RING + 1, 12):
        assert s.instants[k % SyncClock.RING] == pytest.approx(k * PERIOD)


def test_the_counter_runs_from_1_to_its_overflow_and_a_bus_without_it_gets_a_plain_sync():
    s = SyncClock(2, PERIOD, 2)
    seen = []
    for _ in range(p.SYNC_COUNTER_OVERFLOW + 1):
        s.advance()
        seen.append(s.frame.data[0])
    assert seen == [*range(1, p.SYNC_COUNTER_OVERFLOW + 1), 1]
    s.counted[1] = False
    assert len(s.frame.data) == 1 and len(s.plain.data) == 0
    assert s.frame.arbitration_id == s.plain.arbitration_id == p.SYNC


def test_targets_are_behind_their_sync_past_a_share_of_a_period():
    s = SyncClock(2, PERIOD, 1)
    after = SyncClock.RESEND_AFTER
    assert not s.behind(0.001, 0.001 + after * PERIOD, after)
    assert s.behind(0.001, 0.001 + after * PERIOD + 1e-6, after)
    assert not s.behind(0.0, 1.0, np.inf)  # never: resending off


def test_a_write_counts_as_sent_at_its_sync_else_now():
    s = SyncClock(2, PERIOD, 1)
    s.begin_write()
    assert s.sent_instant(5.0) == 5.0  # no SYNC yet
    s.sent(4.9, setup=False)
    assert s.sent_instant(5.0) == 4.9
    s.begin_write()  # the next write, which sent none (within half a period)
    assert s.sent_instant(5.0) == 5.0 and s.last == 4.9
