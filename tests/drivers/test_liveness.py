"""The liveness rules against a clock written by hand: silence counted per read up to the
feedback timeout; simulated drives that were not run (their step stamp old) ridden through
up to ``DRIVES_STALL_LIMIT``, the heartbeat's timeout lengthened by the stall; beyond it, the
timeout's error names the hung simulator."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.liveness import DRIVES_STALL, DRIVES_STALL_LIMIT, Liveness
from drivers.vocabulary import DriverStats, WinchStates

PERIOD = 0.004  # s: 250 Hz
FEEDBACK_TIMEOUT = 0.030  # s
HEARTBEAT_TIMEOUT = 0.5  # s


def liveness(simulated: bool) -> tuple[Liveness, WinchStates, np.ndarray]:
    lv = Liveness(2, PERIOD, np.full(2, 100.0), DriverStats(), FEEDBACK_TIMEOUT,
                  HEARTBEAT_TIMEOUT)  # fmt: skip
    stamp = np.zeros(1)
    if simulated:
        lv.drives_ran_at = stamp
    lv.started = True
    return lv, WinchStates(2), stamp


def read(lv: Liveness, states: WinchStates, t: float, fed: bool) -> bool:
    """One cycle's read at ``t`` s: every cable's feedback and heartbeat arrived (``fed``)
    or none; whether a limit was passed."""
    lv.fresh[:] = fed
    if fed:
        lv.fb_stamp[:] = t
        lv.last_hb[:] = t
    return lv.update(t, lv.read_gap(t), states)


@pytest.mark.parametrize("simulated", [False, True])
def test_silence_faults_after_the_feedback_timeout_when_the_drives_ran(simulated):
    """Drives that ran (real ones; simulated ones whose stamp follows the clock) and did not
    answer: the timeout trips on the read that passes 30 ms of silence, not before."""
    lv, states, stamp = liveness(simulated)
    t = 0.0
    assert not read(lv, states, t, True)
    late_at = None
    for i in range(1, 20):
        t = i * PERIOD
        stamp[0] = t - 0.0005  # the simulator stepped half a millisecond ago
        if read(lv, states, t, False):
            late_at = t
            break
    assert late_at == pytest.approx(8 * PERIOD)  # 32 ms > 30 ms: the 8th silent read
    err = lv.error(0, late_at, "drive 1", "feedback", late_at)
    assert err is not None and "no feedback for 32.0 ms of running cycles" in str(err)
    assert "simulated robot" not in str(err) and lv.stalled_reads[0] == 0


def test_a_starved_simulator_is_ridden_through_and_a_hung_one_is_named():
    """The simulator's stamp stops at 0.1 s for 400 ms (under the limit): 100 silent reads,
    no timeout, neither the feedback's nor the heartbeat's (0.5 s after the last one at 0 s,
    lengthened by the stall); it steps again and answers. Then it stops for good: the reads'
    silence counts once its stall passes the limit, and the error says it hung."""
    lv, states, stamp = liveness(True)
    assert not read(lv, states, 0.0, True)
    stamp[0] = t = 0.1
    for i in range(1, 101):  # 0.4 s of deaf drives
        t = 0.1 + i * PERIOD
        assert not read(lv, states, t, False), t
    # the first, 4 ms after the last step, counted (at most two periods); the 99 others not
    assert lv.stalled_reads[0] == 99 and lv.silent.max() == pytest.approx(2 * PERIOD)
    # 0.501 s since the last heartbeat, past its 0.5 s but for the stall's 0.401 s
    t = 0.5 + 0.001
    assert not read(lv, states, t, False)
    lv.drives_ran_at = None  # real drives: that heartbeat's silence is a timeout
    assert read(lv, states, t, False) and "no heartbeat for 0.501 s" in str(
        lv.error(0, t, "drive 1", "feedback", t))
    lv.drives_ran_at = stamp
    stamp[0] = t  # it stepped: the backlog answered
    assert not read(lv, states, t + PERIOD, True)
    # hung: the stamp never moves again
    stamp[0] = t + PERIOD
    tripped = None
    for i in range(2, 400):
        now = t + i * PERIOD
        if read(lv, states, now, False):
            tripped = now
            break
    assert tripped is not None
    stall = tripped - stamp[0]
    assert DRIVES_STALL_LIMIT < stall <= DRIVES_STALL_LIMIT + FEEDBACK_TIMEOUT + 2 * PERIOD
    err = lv.error(0, tripped, "drive 1", "feedback", tripped - t)
    assert err is not None and "its process hung, beyond the 500 ms ridden through" in str(err)
    assert f"has not stepped for {stall * 1e3:.0f} ms" in str(err)


def test_a_stamp_just_under_the_stall_counts_the_silence():
    """At ``DRIVES_STALL`` exactly the drives count as run (the simulator steps every 0.5 ms;
    5 ms without a step is a stall, not less)."""
    lv, states, stamp = liveness(True)
    assert not read(lv, states, 0.0, True)
    stamp[0] = PERIOD - DRIVES_STALL
    read(lv, states, PERIOD, False)
    assert lv.silent[0] == pytest.approx(PERIOD) and lv.stalled_reads[0] == 0
    stamp[0] = 2 * PERIOD - DRIVES_STALL - 1e-6
    read(lv, states, 2 * PERIOD, False)
    assert lv.silent[0] == pytest.approx(PERIOD) and lv.stalled_reads[0] == 1
