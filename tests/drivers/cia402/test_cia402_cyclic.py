"""The CiA 402 cyclic codec's kernels (drivers/cia402/cyclic.py) called directly, against
expectations written out here: TPDO1 decoding (32-bit wrap, per-mille torque, dropped steps),
the feedback state (velocity by differences, faults), RPDO1 encoding (the fault-reset edge,
torque per-mille and its int16 range), and the position targets of position mode."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cdprctl.core.numerics import kernel_args
from drivers.cia402 import cyclic
from drivers.cia402 import protocol as p

PS = p.PowerState
RATED = 2.5  # N·m: a drive's rated torque (0x6076)
CPR = 4096  # counts per motor revolution
RAD = 2 * math.pi / CPR  # rad per count
MAX_SPEED = 500.0  # rad/s: the fastest a motor turns
PERIOD = 0.002  # s


class Codec:
    """The driver's decoding state for ``m`` cables (as drivers/cia402/driver.py makes it)."""

    def __init__(self, m: int = 3):
        self.m = m
        self.raw = np.zeros((m, 3), dtype=np.int64)
        self.counts = np.zeros(m, dtype=np.int64)
        self.ps = np.full(m, int(PS.NOT_READY_TO_SWITCH_ON), dtype=np.int64)
        self.emcy = np.zeros(m, dtype=np.int64)
        self.prev = np.full((m, 2), -math.inf)
        self.decoded = kernel_args(
            cyclic.Decoded(self.raw, self.counts, self.ps, self.emcy, self.prev)
        )
        self.torque = np.zeros(m)
        self.fresh = np.zeros(m, dtype=np.bool_)
        self.fb_stamp = np.full(m, -math.inf)

    def tpdo1(self, stamp: float, *frames: tuple[int, int, int, int]) -> int:
        """Frames (cable, statusword, torque per-mille, position counts) sampled at ``stamp``
        s; returns how many were dropped."""
        f = np.array(frames, dtype=np.int64).reshape(-1, 4)
        self.fresh[:] = False
        # no SYNC sent (sequence 0): every frame stamped at ``stamp``
        return int(cyclic.tpdo1_synced_kernel(
            len(f), f, np.zeros(8), np.zeros(1, dtype=np.int64), np.zeros(self.m, dtype=np.int64),
            2, stamp, PERIOD,
            np.full(self.m, MAX_SPEED), np.full(self.m, RAD), RATED, cyclic.POWER_STATE_OF_SW7,
            self.decoded, self.torque, self.fresh, self.fb_stamp, np.zeros(self.m),
        ))  # fmt: skip


OP = p.STATUSWORD_OF[PS.OPERATION_ENABLED]


def test_the_first_frame_sets_and_later_ones_step_through_the_32_bit_wrap():
    c = Codec()
    assert c.tpdo1(1.0, (0, OP, 0, 2**31 - 100), (1, OP, 0, -5)) == 0
    assert list(c.counts[:2]) == [2**31 - 100, -5] and list(c.fresh) == [True, True, False]
    assert c.tpdo1(1.002, (0, OP, 0, -(2**31) + 101), (1, OP, 0, -156)) == 0  # odd steps
    assert list(c.counts[:2]) == [2**31 + 101, -156]
    assert c.tpdo1(1.004, (0, OP, 0, 2**31 - 50)) == 0  # back through the wrap: -151
    assert c.counts[0] == 2**31 - 50 and c.fb_stamp[0] == 1.004 and c.fb_stamp[1] == 1.002


def test_torque_actual_is_per_mille_of_the_rated_torque():
    c = Codec()
    c.tpdo1(1.0, (0, OP, 1000, 0), (1, OP, -333, 0), (2, OP, 32767, 0))
    assert c.torque[0] == RATED
    assert c.torque[1] == pytest.approx(-0.333 * RATED, rel=1e-12)
    assert c.torque[2] == pytest.approx(32.767 * RATED, rel=1e-12)


def test_every_statusword_decodes_through_the_table_as_the_protocol_says():
    """All 2^16 statuswords: the power state the cyclic table gives (bits 0-6) is
    ``decode_statusword``'s (CiA 402 Table 30, tested against the canopen package)."""
    c = Codec(1)
    for sw in range(0x10000):
        c.tpdo1(1.0 + sw * PERIOD, (0, sw, 0, 0))
        assert c.ps[0] == p.decode_statusword(sw), hex(sw)


def test_a_step_no_motor_can_make_is_dropped_counted_and_forgiven_when_one_fits():
    """The most a motor turns between samples: MAX_SPEED × (the time since the last accepted
    one + a period of slack). Beyond it the frame is dropped whole (state, torque, position),
    the implausible ones in a row counted; one plausible frame resets the count. A dropped
    frame does not stop the frames after it being read."""
    c = Codec()
    c.tpdo1(10.0, (0, OP, 0, 0), (1, OP, 0, 0))
    most = MAX_SPEED * (PERIOD + PERIOD) / RAD  # counts, 2 ms after the last sample
    ok, too_far = int(0.9 * most), int(1.1 * most)
    fault = p.STATUSWORD_OF[PS.FAULT]
    assert c.tpdo1(10.002, (0, fault, 700, too_far), (1, OP, 100, ok)) == 1
    assert c.counts[0] == 0 and c.ps[0] == PS.OPERATION_ENABLED and c.torque[0] == 0.0
    assert c.raw[0, 2] == 1 and not c.fresh[0] and c.fb_stamp[0] == 10.0
    assert c.counts[1] == ok and c.fresh[1] and c.torque[1] == pytest.approx(0.1 * RATED)
    assert c.tpdo1(10.004, (0, OP, 0, 2 * too_far)) == 1  # 4 ms since the last accepted
    assert c.raw[0, 2] == 2
    assert c.tpdo1(10.006, (0, OP, 0, int(0.9 * MAX_SPEED * (0.006 + PERIOD) / RAD))) == 0
    assert c.raw[0, 2] == 0 and c.raw[0, 1] == 1 and c.fresh[0]


def state(c: Codec, derived: bool, generic: np.ndarray | None = None) -> tuple:
    position, velocity = np.full(c.m, 7.0), np.full(c.m, 9.0)  # what a read left
    st, code = np.zeros(c.m, dtype=np.int64), np.zeros(c.m, dtype=np.int64)
    gen = generic if generic is not None else np.arange(8, dtype=np.int64) + 10
    fault = cyclic.state_kernel(c.fresh, c.fb_stamp, np.full(c.m, RAD), derived, gen,
                                c.decoded, (position, velocity, st, code))  # fmt: skip
    return bool(fault), position, velocity, st, code


def test_positions_of_the_fresh_cables_and_velocities_by_their_sample_instants():
    c = Codec()
    c.tpdo1(1.0, (0, OP, 0, 1000), (1, OP, 0, 1000))
    _, pos, vel, _, _ = state(c, derived=True)
    assert pos[0] == 1000 * RAD and pos[2] == 7.0  # cable 2: no frame, as it was
    assert vel[0] == 9.0  # one sample: no velocity yet
    c.tpdo1(1.004, (0, OP, 0, 1400))  # 400 counts in 4 ms
    _, pos, vel, _, _ = state(c, derived=True)
    assert vel[0] == pytest.approx(400 * RAD / 0.004, rel=1e-12) and vel[1] == 9.0
    c.tpdo1(1.006, (0, OP, 0, 1500))
    _, _, vel, _, _ = state(c, derived=False)  # the drive's own velocity (TPDO2) is used
    assert vel[0] == 9.0
    c.tpdo1(1.006, (0, OP, 0, 1500))  # the same instant again: no division by zero
    _, _, vel, _, _ = state(c, derived=True)
    assert vel[0] == 9.0
    c.fb_stamp[0] = 1.005  # an instant before the last (a clock stepped back): no velocity
    _, _, vel, _, _ = state(c, derived=True)
    assert vel[0] == 9.0
    c = Codec()  # one cable sampled twice while the others have never been
    c.tpdo1(2.0, (0, OP, 0, 0))
    state(c, derived=True)
    c.tpdo1(2.002, (0, OP, 0, 100))
    _, _, vel, _, _ = state(c, derived=True)
    assert vel[0] == pytest.approx(100 * RAD / 0.002, rel=1e-12) and vel[1] == 9.0


def test_the_drive_state_fault_code_and_fault_flag_of_each_cable():
    c = Codec()
    c.ps[:] = [PS.OPERATION_ENABLED, PS.FAULT_REACTION_ACTIVE, PS.SWITCHED_ON]
    fault, _, _, st, code = state(c, derived=True)
    assert not fault and list(st) == [14, 16, 13] and list(code) == [0, 0, 0]
    c.emcy[1] = 0x2310
    fault, _, _, st, code = state(c, derived=True)
    assert fault and list(code) == [0, 0x2310, 0]
    c.emcy[1] = 0
    c.ps[2] = PS.FAULT
    assert state(c, derived=True)[0]
    for code_now in (1, 0xFFFF):  # any code is a fault
        c.ps[2], c.emcy[0] = PS.OPERATION_ENABLED, code_now
        assert state(c, derived=True)[0]


def controlwords(ps: list[PS], reset: int, enable: bool, torques=None, emcy=None) -> tuple:
    m = len(ps)
    out = np.full((m, 2), 12345, dtype=np.int64)  # what the last cycle left
    em = np.array(emcy if emcy is not None else [0x8611] * m, dtype=np.int64)
    tq = np.zeros(m) if torques is None else np.asarray(torques, dtype=float)
    cyclic.controlword_kernel(tq, np.array([int(s) for s in ps], dtype=np.int64), em, reset,
                              enable, RATED, cyclic.CONTROLWORD_TOWARDS_ENABLED, out)  # fmt: skip
    return list(out[:, 0]), list(out[:, 1]), list(em)


def test_the_fault_reset_is_a_rising_edge_to_the_drives_in_fault_only():
    """CiA 402: a fault resets on the 0 → 1 edge of controlword bit 7. While a reset counts
    down (the driver starts it at 4), the drives in fault (or reacting to one) get 0x0000
    while more than 2 cycles are left, then 0x0080, the EMCY code cleared with it; the other
    drives meanwhile go on towards enabled."""
    ps = [PS.FAULT, PS.FAULT_REACTION_ACTIVE, PS.SWITCHED_ON, PS.OPERATION_ENABLED]
    cw, _, em = controlwords(ps, reset=3, enable=True)
    assert cw == [0x0000, 0x0000, 0x000F, 0x000F] and em == [0x8611] * 4
    for reset in (2, 1):
        cw, _, em = controlwords(ps, reset, enable=True)
        assert cw == [0x0080, 0x0080, 0x000F, 0x000F] and em == [0, 0, 0x8611, 0x8611]
    cw, _, em = controlwords(ps, reset=0, enable=True)  # no reset: towards enabled (Fig. 14)
    assert cw == [0x0000, 0x0000, 0x000F, 0x000F] and em == [0x8611] * 4
    cw, _, _ = controlwords([PS.SWITCH_ON_DISABLED, PS.READY_TO_SWITCH_ON], 0, enable=True)
    assert cw == [0x0006, 0x0007]
    cw, _, _ = controlwords(ps, reset=0, enable=False)
    assert cw == [0x0000] * 4


def test_torques_go_out_per_mille_rounded_half_to_even_within_int16():
    t = [RATED, -2.5 * RATED, 0.0005 * RATED, 0.0015 * RATED, 40 * RATED, -40 * RATED]
    _, pm, _ = controlwords([PS.OPERATION_ENABLED] * len(t), 0, True, torques=t)
    assert pm == [1000, -2500, 0, 2, 32767, -32767]


def test_a_target_rate_only_between_cycles_less_than_a_second_apart():
    last, rate = np.array([1.0, 1.0]), np.zeros(2)
    max_speed = np.array([100.0, 10.0])
    for gap, want in ((0.004, [50.0, 10.0]), (0.0, [0.0, 0.0]), (-0.5, [0.0, 0.0]),
                      (1.0, [0.0, 0.0]), (1.5, [0.0, 0.0])):  # fmt: skip
        last[:] = 1.0
        cyclic.target_rates_kernel(np.array([1.2, 1.2]), 5.0 + gap, last, 5.0, max_speed, rate)
        assert list(rate) == pytest.approx(want), gap
        assert list(last) == [1.2, 1.2]


def test_position_targets_carried_on_and_in_32_bit_counts():
    out = np.zeros(2)
    cyclic.carry_targets_kernel(np.array([1.0, -2.0]), np.array([3.0, 4.0]), 0.001, out)
    assert list(out) == pytest.approx([1.003, -1.996], abs=1e-15)
    counts = np.zeros(3, dtype=np.int64)
    cyclic.target_counts_kernel(np.array([101 * RAD, -(2**31 + 3) * RAD, (2**32 + 7) * RAD]),
                                np.full(3, RAD), counts)  # fmt: skip
    assert list(counts) == [101, 2**31 - 3, 7]


def sync_case(answered: int, step: int, rate: float, seq: int = 10, period: float = 0.004,
              last: int = 1000):  # fmt: skip
    """``sync_instant`` for cable 0 whose last sample (32-bit position ``last``) was at SYNC
    5's instant, moving at ``rate`` counts/s, its new frame ``step`` counts on (wrapping at
    32 bits): (the SYNC chosen, its instant)."""
    syncs = np.full(8, np.nan)
    for k in range(seq - 7, seq + 1):
        syncs[k % 8] = k * period
    raw = np.array([[last, 1, 0]], dtype=np.int64)
    ans = np.array([answered], dtype=np.int64)
    pos = (last + step + 2**31) % 2**32 - 2**31
    stamp = cyclic.sync_instant(0, pos, syncs, seq, ans, 4, raw, np.array([5 * period]),
                                np.array([rate]), -1.0)  # fmt: skip
    return int(ans[0]), stamp


def test_a_tpdo_is_stamped_at_the_sync_it_answers():
    """One TPDO1 per SYNC: the next answer is to the SYNC after the last answered; one lost
    (a moving drive's step fits a newer SYNC) is found by the drive's rate; at rest the
    sequence decides; a SYNC already answered is never chosen again, whatever the rate says
    (after a stall the rate is of before it)."""
    rate = 250_000.0  # counts/s: 1000 counts a 4 ms period
    assert sync_case(answered=5, step=1000, rate=rate) == (6, 6 * 0.004)  # late by 4 SYNCs
    assert sync_case(answered=5, step=3000, rate=rate) == (8, 8 * 0.004)  # two lost
    assert sync_case(answered=5, step=1, rate=0.0)[0] == 6  # at rest: the sequence
    assert sync_case(answered=9, step=0, rate=rate)[0] == 10  # the stopped drive after a stall
    assert sync_case(answered=10, step=5000, rate=rate)[0] == 10  # never past the newest
    assert sync_case(answered=1, step=5000, rate=rate)[0] == 10  # lag_max 4: from SYNC 6 on
    # the sequence's SYNC fits 2 counts worse than the next: within SYNC_FIT_COUNTS, kept
    assert sync_case(answered=5, step=1501, rate=rate)[0] == 6
    assert sync_case(answered=5, step=1506, rate=rate)[0] == 7  # 12 counts worse: the fit wins
    # across the 32-bit wrap of the position, the step is still 1000 counts: SYNC 6
    assert sync_case(answered=5, step=1000, rate=rate, last=2**31 - 500)[0] == 6
    assert sync_case(answered=5, step=3000, rate=rate, last=2**31 - 500)[0] == 8
    assert cyclic.sync_instant(0, 0, np.zeros(8), 0, np.zeros(1, dtype=np.int64), 4,
                               np.zeros((1, 3), dtype=np.int64), np.zeros(1), np.zeros(1),
                               -1.0) == -1.0  # before the first SYNC: the fallback  # fmt: skip


def test_the_rpdo1_kernel_packs_as_struct_does():
    """``pack_rpdo1_kernel`` writes each RPDO1 in place as ``RPDO1_CSP_STRUCT`` (position
    mode) or ``RPDO1_STRUCT`` (torque mode) packs it: the fields' extremes, signs, random."""
    rng = np.random.default_rng(1)
    position = np.array([True, False, True, False])
    frames = [bytearray(8 if s else 4) for s in position]
    views = tuple(np.frombuffer(b, dtype=np.uint8) for b in frames)
    extremes = [(0xFFFF, -32767, -(2**31)), (0, 32767, 2**31 - 1), (0x80, -1, -1)]
    draws = [
        (int(rng.integers(0, 0x10000)), int(rng.integers(-32767, 32768)),
         int(rng.integers(-(2**31), 2**31)))
        for _ in range(200)
    ]  # fmt: skip
    for cw, pm, n in extremes + draws:
        fields = np.array([[cw, pm]] * 4, dtype=np.int64)
        cyclic.pack_rpdo1_kernel(fields, np.full(4, n, dtype=np.int64), position, views)
        assert bytes(frames[0]) == p.RPDO1_CSP_STRUCT.pack(cw, n, pm)
        assert bytes(frames[1]) == p.RPDO1_STRUCT.pack(cw, pm)


def test_the_tpdo1_decoding_kernel_unpacks_as_struct_does():
    """``decode_tpdo1_kernel`` reads TPDO1 bytes as ``TPDO1_STRUCT`` unpacks them: the
    fields' extremes, signs, random bytes; only the first ``n`` rows written."""
    rng = np.random.default_rng(2)
    raw = rng.integers(0, 256, size=(40, 8), dtype=np.uint8)
    raw[0] = [0xFF, 0xFF, 0x00, 0x80, 0x00, 0x00, 0x00, 0x80]  # 0xFFFF, -32768, -2**31
    raw[1] = [0x00, 0x00, 0xFF, 0x7F, 0xFF, 0xFF, 0xFF, 0x7F]  # 0, 32767, 2**31 - 1
    cables = np.arange(40, dtype=np.int64) % 8
    frames = np.full((40, 4), -7, dtype=np.int64)
    cyclic.decode_tpdo1_kernel(39, raw, cables, frames)
    for i in range(39):
        assert frames[i].tolist() == [int(cables[i]), *p.TPDO1_STRUCT.unpack(raw[i].tobytes())]
    assert frames[39].tolist() == [-7] * 4
