"""The CiA 402 driver's own rules at frame level (the scripted peer of test_drivers_frames, in
simulated time): which frames it takes and which it ignores, a fault the statusword alone
reports, the NMT start it sends again, the torque limit's object at its ceiling, the targets
sent again for a SYNC held up after them."""

from __future__ import annotations

import contextlib
import dataclasses
import itertools

import numpy as np
import pytest
from conftest import CONFIG, in_torque_mode
from test_drivers_frames import (
    Cia402Script,
    active_rowc,
    cycles,
    frame,
    make,
    over_current_on_node_4,
)

from cdprctl.robot_file import load_robot
from drivers import DriveFaultError, DriverOperationError, Lifecycle
from drivers.cia402 import protocol as p


@contextlib.contextmanager
def first_read(seed):
    """(driver, its peer, the frames it ignored so far): rowc's eight drives configured and
    their first feedback read."""
    drv, peer = make(seed, Cia402Script(range(1, 9)))
    with drv:
        drv.configure()
        drv.read(peer.t)
        yield drv, peer, drv.stats.frames_ignored


@pytest.fixture
def seed():
    return in_torque_mode(load_robot(CONFIG / "seed000.toml"))


def test_a_fault_the_statusword_alone_reports_is_that_drives_fault(seed):
    """A drive in FAULT that sent no EMCY (lost, or a drive that sends none): a drive fault
    of its cable all the same, said to come from the statusword."""
    script = Cia402Script(range(1, 9))
    drv, peer = make(seed, script)
    with drv:
        drv.configure()
        drv.activate()
        script.statusword[3] = 0x0218  # fault, no EMCY
        cycles(drv, peer, 3)
        assert drv.lifecycle is Lifecycle.ERROR
        assert isinstance(drv.error, DriveFaultError)
        assert drv.error.cable == 2 and drv.error.code == 0
        assert "fault (statusword)" in str(drv.error)


def test_a_short_emcy_is_ignored_and_counted_and_a_padded_heartbeat_is_read_from_its_first_byte(
    seed,
):
    """An EMCY must be 8 bytes (CiA 301 §7.2.7): a 4-byte one is no fault and no velocity
    (TPDO2's length), one frame ignored; a heartbeat padded to 2 bytes (some devices pad)
    gives its NMT state from byte 0."""
    with first_read(seed) as (drv, peer, before):
        velocity = drv.states.velocity.copy()
        peer.bus.send(frame(p.EMCY + 2, b"\x10\x23\x01\x00"))
        peer.bus.send(frame(p.HEARTBEAT + 5, bytes([p.HB_PRE_OPERATIONAL, 0x05])))
        drv.read(peer.t + 0.001)
        assert drv.stats.frames_ignored == before + 1
        assert drv.lifecycle is Lifecycle.INACTIVE and int(drv.feedback.emcy[1]) == 0
        np.testing.assert_array_equal(drv.states.velocity, velocity)
        assert drv.feedback.nmt_state[4] == p.HB_PRE_OPERATIONAL


class LateDrive(Cia402Script):
    """Drive ``node`` sends nothing until ``after`` s: its NMT start was lost."""

    def __init__(self, node: int, after: float):
        super().__init__(range(1, 9))
        self.node, self.after = node, after
        self.silent.add(node)

    def __call__(self, msg, t):
        if t >= self.after:
            self.silent.discard(self.node)
        return super().__call__(msg, t)


def test_a_lost_nmt_start_is_sent_again_every_half_second_until_every_drive_answers(seed):
    script = LateDrive(5, 1.3)
    drv, peer = make(seed, script)
    with drv:
        drv.configure(timeout=3.0)
        starts = sorted({t for t, arb, d in peer.rx if arb == p.NMT and d[0] == p.NMT_START})
        assert drv.lifecycle is Lifecycle.INACTIVE
    again = starts[1:]  # the first: the set-up's own
    assert len(again) == 2, starts  # at 0.5 and 1.0 s into the wait, then drive 5 answered
    for a, b in itertools.pairwise(again):
        assert b - a == pytest.approx(0.5, abs=0.0021)
    for t in again:  # each in the first period past a half second
        assert t % 0.5 < 0.0021 + 1e-9, t


def test_0x6072_is_the_winchs_torque_limit_in_per_mille_of_the_rated_torque(seed):
    """0x6072 (CiA 402 §6.9.3): per mille of the rated torque, here seed000's winch limits
    over [drives] rated_torque, rounded to the nearest."""
    script = Cia402Script(range(1, 9))
    drv, _ = make(seed, script)
    with drv:
        drv.configure()
    for c, cable in enumerate(seed.cables):
        node = seed.drives.node_of(c)[1]
        per_mille = cable.winch.torque_limit / seed.drives.rated_torque * 1000.0
        assert script.objects[node][(p.OD_MAX_TORQUE, 0)] == round(per_mille)
        assert abs(per_mille - round(per_mille)) < 0.4  # the rounding decides nothing


def test_a_torque_limit_beyond_what_0x6072_holds_is_written_at_its_ceiling(tmp_path):
    """0x6072 is UNSIGNED16 per mille of the rated torque: a winch limit of 5 N·m over a
    rated 0.05 N·m (100,000 ‰) is written as 0xFFFF, not wrapped."""
    f = tmp_path / "r.toml"
    f.write_text(f'base = "{CONFIG / "seed000.toml"}"\n[drives]\nrated_torque = 0.05\n')
    model = in_torque_mode(load_robot(f))
    script = Cia402Script(range(1, 9), rated_mnm=50)
    drv, _ = make(model, script)
    with drv:
        drv.configure()
    assert {script.objects[n][(p.OD_MAX_TORQUE, 0)] for n in range(1, 9)} == {0xFFFF}


def test_targets_are_sent_again_when_their_sync_goes_out_a_quarter_period_after_them():
    """Position mode: the SYNC held up past a quarter of a period after the RPDOs (the VM
    took the CPU between them) sends the targets again for the SYNC's instant; held up less,
    once only; held up again at every check, three times at most, then the SYNC goes out (a
    write's work is bounded)."""

    def resent(hold: float, again: bool = False) -> int:
        with active_rowc() as (ls, base):
            d = ls.driver
            calls = []
            clock = d.clock

            def held_clock():  # the write's first clock read, then ``hold`` s later (again:
                calls.append(1)  # ``hold`` more at each read)
                return clock() + hold * (len(calls) - 1 if again else min(len(calls) - 1, 1))

            t = ls.net.time
            d.read(t)
            d.clock = held_clock
            d.write(t, np.zeros(8), targets=base)
            d.clock = clock
            return d.resent_targets

    period = 0.004
    assert resent(0.2 * period) == 0
    assert resent(0.5 * period) == 1
    assert resent(0.5 * period, again=True) == 3


def test_frames_of_the_wrong_length_for_their_kind_are_ignored_and_counted(seed):
    """Each kind of frame has its length (CiA 301; cdprctl's mapping): a 4-byte TPDO1 is no
    velocity, an 8-byte TPDO2 no EMCY and no SDO answer, a 6- or 2-byte TPDO2 no velocity, an empty
    heartbeat no sign of life, a 4-byte SDO answer no answer (CiA 301: always 8) — each one
    frame ignored, nothing of the drive changed."""
    with first_read(seed) as (drv, peer, before):
        velocity, last_hb = drv.states.velocity.copy(), drv.liveness.last_hb.copy()
        for arb, data in [
            (p.TPDO1 + 3, b"\x01\x02\x03\x04"),
            (p.TPDO2 + 3, bytes(range(1, 9))),
            (p.TPDO2 + 3, bytes(range(1, 7))),
            (p.HEARTBEAT + 3, b""),
            (p.SDO_TX + 3, b"\x43\x00\x10\x00"),
            (p.TPDO2 + 3, b"\x01\x02"),
        ]:
            peer.bus.send(frame(arb, data))
        drv.read(peer.t + 0.001)
        assert drv.stats.frames_ignored == before + 6
        assert drv.lifecycle is Lifecycle.INACTIVE and int(drv.feedback.emcy[2]) == 0
        assert 2 not in drv.feedback.sdo_reply
        np.testing.assert_array_equal(drv.states.velocity, velocity)
        np.testing.assert_array_equal(drv.liveness.last_hb, last_hb)


def test_a_cycle_whose_time_is_ahead_of_the_clock_sends_its_targets_for_its_time():
    """Position mode, targets moving at 2 rad/s: a write whose cycle time is 0.5 ms ahead of
    the clock (a time from another clock, or a wake-up before it) sends the targets of its
    time — carried on for a late send, never carried back: a target behind the last one
    sent is a reversal of the drive's interpolation (0.5 ms: below the quarter period past
    which they would go out again for the SYNC anyway)."""

    def sent_target(ahead: float) -> int:
        with active_rowc() as (ls, base):
            d = ls.driver
            for k in range(3):
                t = ls.net.time + (ahead if k == 2 else 0.0)
                d.read(ls.net.time)
                d.write(t, np.zeros(8), targets=base + 0.01 * k)
                ls.net.advance(0.004)
            return int(ls.net.drives[0].axis.target_counts)

    assert sent_target(0.0005) == sent_target(0.0)


def test_a_drive_found_in_fault_is_not_reset_until_the_operator_asks(seed):
    """A drive still in FAULT from before cdprctl started: no RPDO1 carries the fault-reset
    bit (0x80) on the driver's own — a latched fault is cleared only by ``recover`` (the
    operator's acknowledgement), then with a rising edge."""
    script = Cia402Script(range(1, 9))
    script.state[4] = p.PowerState.FAULT
    drv, peer = make(seed, script)
    with drv:
        drv.configure()
        cycles(drv, peer, 6)

        def controlwords():
            return [int.from_bytes(d[:2], "little") for d in peer.sent(p.RPDO1 + 4)]

        assert len(controlwords()) >= 5 and not any(cw & 0x80 for cw in controlwords())
        assert script.state[4] is p.PowerState.FAULT
        assert drv.lifecycle is Lifecycle.ERROR and drv.error.cable == 3
        drv.recover()
        assert 0x80 in controlwords() and script.state[4] is not p.PowerState.FAULT


def test_targets_are_carried_only_between_cycles_of_running_drives():
    """Position mode, configured but not enabled, within the first second of the clock
    (lock-step starts at 0): targets stepping 1 rad a cycle have no rate while the drives are
    not running, so a cycle held up 3 ms before its send sends the same targets as one on
    time — no last cycle is 'a cycle at t = 0'."""
    from sim_backend.network import LockStep

    def sent(held: float) -> list[bytes]:
        with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
            d = ls.driver
            d.configure()
            base = d.read(ls.net.time).position.copy()
            for k in range(3):
                t = ls.net.time
                assert t < 1.0 and d.lifecycle is Lifecycle.INACTIVE
                d.read(t)
                if k == 2:
                    ls.net.advance(held)
                d.write(t, np.zeros(8), targets=base + 1.0 * k)
                ls.net.advance(0.004 - (held if k == 2 else 0.0))
            return [bytes(msg.data) for msg in d._rpdo]

    assert sent(0.003) == sent(0.0)


def test_the_first_cycle_of_running_drives_carries_no_target_rate():
    """Position mode, enabled cycle by cycle (``begin_activate``, as the daemon does) within
    the clock's first second (lock-step starts at 0): the enable's cycles, the drives not
    yet running, are no last cycle, so the first running cycle's targets, 0.5 rad on and held
    up 3 ms before their send, go out as they would on time — no rate from the enable's
    targets over the time since t = 0."""
    from sim_backend.network import LockStep

    def sent(held: float) -> list[bytes]:
        with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
            d = ls.driver
            d.configure()
            base = d.read(ls.net.time).position.copy()
            d.begin_activate()
            for _ in range(100):
                t = ls.net.time
                d.read(t)
                if d.lifecycle is Lifecycle.ACTIVE:
                    break
                d.write(t, np.zeros(8), targets=base)
                ls.net.advance(0.004)
            assert 0.0 < t < 1.0 and d.lifecycle is Lifecycle.ACTIVE
            ls.net.advance(held)
            d.write(t, np.zeros(8), targets=base + 0.5)
            return [bytes(msg.data) for msg in d._rpdo]

    assert sent(0.003) == sent(0.0)


def test_frames_beyond_a_full_batch_are_applied_after_it_and_only_they(seed):
    """A read held up five periods with one drive silent: 35 TPDO1s, more than a batch of 4
    per drive (32). The frames beyond it are applied after it and only they — each drive
    ends at its newest position, none back at a frame the batch already applied."""
    script = Cia402Script(range(1, 9))
    drv, peer = make(seed, script)
    with drv:
        drv.configure()
        drv.read(peer.t)
        script.silent.update(range(1, 9))  # the frames below are the only ones
        sw = p.STATUSWORD_OF[p.PowerState.SWITCH_ON_DISABLED]
        for k in range(1, 6):
            for n in range(1, 8):  # node 8 silent
                peer.bus.send(frame(p.TPDO1 + n, p.TPDO1_STRUCT.pack(sw, 0, 10 * k + n)))
        drv.read(peer.t + 0.001)
        counts = np.round(drv.states.position[:7] / drv.rad_per_count[:7])
        np.testing.assert_array_equal(counts, [50 + n for n in range(1, 8)])


def test_the_controllers_heartbeat_goes_out_from_the_first_sync_as_a_standard_frame(seed):
    """The master's own heartbeat (0x700 + its node id, OPERATIONAL; CiA 301 §7.2.8.3): an
    11-bit frame — a drive consuming heartbeats (0x1016) matches no 29-bit one — sent with the
    very first SYNC and then every ``heartbeat_period`` (here longer than the set-up, whose
    SDO exchanges come first)."""
    seed = dataclasses.replace(seed, drives=dataclasses.replace(seed.drives, heartbeat_period=0.5))
    drv, peer = make(seed, Cia402Script(range(1, 9)))
    with drv:
        drv.configure()
        start = peer.t
        cycles(drv, peer, 600)
    assert start < seed.drives.heartbeat_period
    arb = p.HEARTBEAT + seed.drives.controller_node_id
    sent = [(t, m) for (t, a, _), m in zip(peer.rx, peer.messages, strict=True) if a == arb]
    assert all(not m.is_extended_id and bytes(m.data) == bytes([p.HB_OPERATIONAL])
               for _, m in sent)  # fmt: skip
    assert sent[0][0] == min(t for t, a, _ in peer.rx if a == p.SYNC)
    gaps = np.diff([t for t, _ in sent])
    assert np.all(np.abs(gaps - seed.drives.heartbeat_period) <= 0.002 + 1e-9), gaps


def test_feedback_is_stamped_with_the_sync_it_was_sampled_for(seed):
    """A drive samples its TPDO1 at the SYNC: the feedback read a period later is that SYNC's
    (``sampled_at``), a period old (``feedback_age``) — not the read's instant."""
    drv, peer = make(seed, Cia402Script(range(1, 9)))
    with drv:
        drv.configure()
        cycles(drv, peer, 3)
        sync_at = max(t for t, a, _ in peer.rx if a == p.SYNC)
        states = drv.read(peer.t)
        np.testing.assert_array_equal(states.sampled_at, sync_at)
        np.testing.assert_allclose(states.feedback_age, peer.t - sync_at, rtol=0, atol=1e-12)
        assert peer.t - sync_at == pytest.approx(0.002)


def test_with_derived_velocity_a_tpdo2_is_not_the_velocity(seed):
    """``velocity_source = "derived"`` (the default): a TPDO2 a drive sends anyway (its own
    DCF mapped one) does not replace the velocity from the positions."""
    assert seed.drives.velocity_source == "derived"
    drv, peer = make(seed, Cia402Script(range(1, 9)))
    with drv:
        drv.configure()
        velocity = drv.read(peer.t).velocity.copy()
        peer.bus.send(frame(p.TPDO2 + 3, p.TPDO2_STRUCT.pack(12345)))
        np.testing.assert_array_equal(drv.read(peer.t + 0.001).velocity, velocity)


def test_an_emcy_is_a_fault_before_the_statusword_says_so(seed):
    """An EMCY with an error code (CiA 301 §7.2.7) is that drive's fault at once, from its
    code, even while its statusword still says it is enabled (the EMCY comes first)."""
    script = Cia402Script(range(1, 9))
    drv, peer = make(seed, script)
    with drv:
        drv.configure()
        drv.activate()
        peer.bus.send(frame(p.EMCY + 6, p.EMCY_STRUCT.pack(0x3210, 1, bytes(5))))
        cycles(drv, peer, 1)
        assert script.state[6] is not p.PowerState.FAULT  # its statusword never said fault
        assert drv.lifecycle is Lifecycle.ERROR and isinstance(drv.error, DriveFaultError)
        assert (drv.error.cable, drv.error.code) == (5, 0x3210)


def test_a_brake_is_commanded_only_while_the_drives_are_not_running():
    """The master's brake command (0x60FE, a brake test) is an SDO exchange: refused in one
    line while the drives run, taken while they are inactive."""
    from sim_backend.network import LockStep

    with LockStep(load_robot(CONFIG / "rowc.toml"), period=0.004) as ls:
        ls.driver.configure()
        ls.driver.command_brake(3, True, 1.0)
        ls.driver.command_brake(3, False, 1.0)
        ls.driver.activate()
        with pytest.raises(DriverOperationError, match="brake command while ACTIVE"):
            ls.driver.command_brake(3, True, 1.0)


def test_a_bus_with_a_drive_without_the_sync_counter_gets_plain_syncs(seed):
    """0x1019 (CiA 301 §7.5.2.22) is optional: where a drive lacks it, that bus's SYNC is the
    plain one — no data byte, an 11-bit frame like every SYNC (a 29-bit 0x080 is no SYNC)."""
    script = Cia402Script(range(1, 9))
    del script.objects[3][(p.OD_SYNC_COUNTER_OVERFLOW, 0)]
    drv, peer = make(seed, script)
    with drv:
        drv.configure()
        cycles(drv, peer, 3)
    syncs = [m for m in peer.messages if m.arbitration_id == p.SYNC]
    assert syncs and all(not m.is_extended_id and bytes(m.data) == b"" for m in syncs)


class _LosesTheFirstReset(Cia402Script):
    """A lossy bus: the first fault-reset controlword (bit 7) to ``node`` never arrives."""

    def __init__(self, nodes, node):
        super().__init__(nodes)
        self.node, self.lost = node, False

    def __call__(self, msg, t):
        if msg.arbitration_id == p.RPDO1 + self.node and msg.data[0] & 0x80 and not self.lost:
            self.lost = True
            return []
        return super().__call__(msg, t)


def test_a_fault_reset_survives_one_lost_frame(seed):
    """The reset edge's 0x0080 goes out in two cycles while the drive still reports its
    fault: one frame lost on the bus does not lose the operator's reset."""
    script = _LosesTheFirstReset(range(1, 9), 4)
    drv, peer = make(seed, script)
    with drv:
        over_current_on_node_4(drv, peer, script)
        assert drv.lifecycle is Lifecycle.ERROR
        drv.recover()
        assert script.lost and script.state[4] is not p.PowerState.FAULT
        assert drv.lifecycle is Lifecycle.INACTIVE
