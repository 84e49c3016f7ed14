"""The ODrive driver frame by frame (CAN Simple, in simulated time): what it takes from each
frame and what it drops, the enable it sends again when a frame is lost, the errors it clears
only when asked. The layouts are written out here with struct, not taken from the driver."""

from __future__ import annotations

import math
import struct

import can
import numpy as np
import pytest
from conftest import CONFIG, in_torque_mode
from test_drivers_frames import ODriveScript, frame, make

from cdprctl.robot_file import load_robot
from drivers import DriverOperationError, DriverTimeoutError, DriveState, Lifecycle
from drivers.odrive import protocol as po

TURN = 2 * math.pi  # rad per turn
HEARTBEAT, ENCODER, TORQUES = 0x01, 0x09, 0x1C  # CAN Simple command ids
SET_AXIS_STATE, CLEAR_ERRORS = 0x07, 0x18
CLOSED_LOOP, IDLE = 8, 1  # ODrive AxisState


@pytest.fixture
def seed():
    return in_torque_mode(load_robot(CONFIG / "seed000.toml"))


def arb(node: int, cmd: int) -> int:
    return node << 5 | cmd


def encoder(node: int, turns: float, turns_per_s: float) -> can.Message:
    return frame(arb(node, ENCODER), struct.pack("<ff", turns, turns_per_s))


def heartbeat(node: int, error: int, state: int, size: int = 8) -> can.Message:
    return frame(arb(node, HEARTBEAT), struct.pack("<IBBBx", error, state, 0, 0)[:size])


def cycle(drv, peer) -> None:
    """A control period of 2 ms: zero torques out, every axis answers, the answers read."""
    drv.write(peer.t, np.zeros(8))
    peer.wait(0.002)
    drv.read(peer.t)


def inject(drv, peer, *frames: can.Message) -> None:
    """``frames`` from the drives' side, then a read 2 ms on (no torque frame: no stream)."""
    for f in frames:
        peer.bus.send(f)
    peer.t += 0.002
    drv.read(peer.t)


def test_encoder_estimates_in_turns_become_rad_and_bad_ones_are_dropped(seed):
    """turns → rad and turns/s → rad/s; a step no motor can make and a frame with a NaN are
    dropped whole (like a lost frame), and the frames after them are still read."""
    drv, peer = make(seed, ODriveScript(range(1, 9)), "odrive")
    with drv:
        drv.configure()
        cycle(drv, peer)
        st = drv.states
        assert st.position[1] == pytest.approx(0.5 * TURN)  # node 2 stands at 0.5 turn
        inject(drv, peer, encoder(2, 0.501, 0.3))
        assert st.position[1] == pytest.approx(0.501 * TURN)
        assert st.velocity[1] == pytest.approx(0.3 * TURN)
        inject(drv, peer, encoder(2, 100.5, 0.3))  # 100 turns in 2 ms
        assert st.position[1] == pytest.approx(0.501 * TURN)
        # fast, plausible steps (0.8 of the most a motor can turn between two samples) far
        # from zero: each is taken — the step is measured in rad, both sides
        most = drv.liveness.max_motor_speed[1] * (0.002 + drv.period)  # rad
        turns = 0.501
        for _ in range(4):
            turns += 0.8 * most / TURN
            inject(drv, peer, encoder(2, turns, 0.0))
            assert st.position[1] == pytest.approx(turns * TURN)
        inject(drv, peer, encoder(2, 2 * turns, 0.0))  # twice as far: a step, not a ratio
        assert st.position[1] == pytest.approx(turns * TURN)
        before3 = st.position[2]
        inject(drv, peer, encoder(3, 0.76, math.nan), encoder(4, 1.01, -0.2))
        assert st.position[2] == before3 and math.isfinite(st.velocity[2])
        assert st.position[3] == pytest.approx(1.01 * TURN)
        assert st.velocity[3] == pytest.approx(-0.2 * TURN)


def test_frames_of_the_wrong_length_are_ignored_and_counted(seed):
    """An estimate or torque frame short of its 8 bytes is ignored (not read as a heartbeat),
    a heartbeat needs its first 7 (error, state, procedure result, trajectory done): each
    ignored frame counted once; a heartbeat of 7 bytes is read."""
    drv, peer = make(seed, ODriveScript(range(1, 9)), "odrive")
    with drv:
        drv.configure()
        cycle(drv, peer)
        st, before = drv.states, drv.stats.frames_ignored
        torque = st.torque.copy()
        short = [
            frame(arb(2, ENCODER), struct.pack("<ff", 0.5, 0.0)[:7]),
            frame(arb(2, TORQUES), struct.pack("<ff", 0.0, 9.0)[:7]),
            heartbeat(2, 0x2000, CLOSED_LOOP, size=6),
        ]
        inject(drv, peer, *short)
        assert drv.stats.frames_ignored - before == 3
        assert np.array_equal(st.torque, torque) and drv.axis_error[1] == 0
        assert drv.axis_state[1] is po.AxisState.IDLE and drv.lifecycle is Lifecycle.INACTIVE
        inject(drv, peer, heartbeat(2, 0, CLOSED_LOOP, size=7))
        assert drv.axis_state[1] is po.AxisState.CLOSED_LOOP_CONTROL
        assert DriveState(st.state[1]) is DriveState.ENABLED
        assert drv.stats.frames_ignored - before == 3


def test_an_axis_state_no_firmware_names_is_unknown_not_a_crash(seed):
    drv, peer = make(seed, ODriveScript(range(1, 9)), "odrive")
    with drv:
        drv.configure()
        cycle(drv, peer)
        inject(drv, peer, heartbeat(5, 0, 99))
        assert drv.axis_state[4] is po.AxisState.UNDEFINED
        assert DriveState(drv.states.state[4]) is DriveState.UNKNOWN
        assert drv.lifecycle is Lifecycle.INACTIVE


class LossyODrive(ODriveScript):
    """An ODriveScript that loses the first closed-loop request sent to ``node``."""

    def __init__(self, nodes, node: int):
        super().__init__(nodes)
        self.lose, self.lost = node, 0

    def __call__(self, msg, t):
        if (msg.arbitration_id == arb(self.lose, SET_AXIS_STATE) and not self.lost
                and struct.unpack("<I", msg.data)[0] == CLOSED_LOOP):  # fmt: skip
            self.lost += 1
            return []
        return super().__call__(msg, t)


def axis_state_requests(peer, node: int) -> list[tuple[float, int]]:
    return [(t, struct.unpack("<I", d)[0]) for t, a, d in peer.rx
            if a == arb(node, SET_AXIS_STATE)]  # fmt: skip


def test_an_enable_lost_on_the_bus_is_sent_again_to_that_axis_only_after_half_a_second(seed):
    """``activate`` asks each axis for closed-loop control once; an axis that did not get
    there (its frame lost) is asked again 0.5 s later — that axis only, not every cycle."""
    drv, peer = make(seed, LossyODrive(range(1, 9), node=3), "odrive")
    with drv:
        drv.configure()
        drv.activate()
        assert drv.lifecycle is Lifecycle.ACTIVE
        asked = {n: [(t, v) for t, v in axis_state_requests(peer, n) if v == CLOSED_LOOP]
                 for n in range(1, 9)}  # fmt: skip
        t0 = asked[1][0][0]
        assert all(len(asked[n]) == 1 and asked[n][0][0] == t0 for n in asked if n != 3)
        assert asked[3][0][0] == t0 and len(asked[3]) == 2  # lost, then sent again
        assert 0.5 < asked[3][1][0] - t0 <= 0.5 + 2 * drv.period
        for _ in range(300):  # 0.6 s more: every axis where it was asked to be, no request
            cycle(drv, peer)
        assert all(len(axis_state_requests(peer, n)) == len(asked[n]) + 1 for n in asked)


class SlowHeartbeats(ODriveScript):
    """Heartbeats every 0.1 s (the ODrive's default rate), not every cycle; errors cleared by
    ``CLEAR_ERRORS``."""

    def __init__(self, nodes):
        super().__init__(nodes)
        self.last_hb = -1.0

    def __call__(self, msg, t):
        out = super().__call__(msg, t)
        if any(f.arbitration_id & 0x1F == HEARTBEAT for f in out):
            if t - self.last_hb < 0.1:
                out = [f for f in out if f.arbitration_id & 0x1F != HEARTBEAT]
            else:
                self.last_hb = t
        return out


def test_errors_are_cleared_when_asked_and_only_then(seed):
    """``CLEAR_ERRORS`` goes out once per axis on a fault reset and never unasked; a cleared
    axis reads as without a fault until a heartbeat says otherwise (a heartbeat every 0.1 s:
    the reads between see no stale error)."""
    script = SlowHeartbeats(range(1, 9))
    drv, peer = make(seed, script, "odrive")

    def clears() -> list[int]:
        return sorted(a >> 5 for _, a, _ in peer.rx if a & 0x1F == CLEAR_ERRORS)

    with drv:
        drv.configure()
        for _ in range(60):
            cycle(drv, peer)
        assert clears() == []
        script.error[6] = 0x00002000  # motor over-temperature
        while drv.lifecycle is not Lifecycle.ERROR and peer.t < 1.0:
            cycle(drv, peer)
        assert drv.lifecycle is Lifecycle.ERROR and drv.axis_error[5] == 0x2000
        t0 = peer.t
        drv.recover()
        assert drv.lifecycle is Lifecycle.INACTIVE
        assert peer.t - t0 < 0.02  # s: not a heartbeat's wait (0.1 s) for a made-up error
        assert clears() == list(range(1, 9))
        for _ in range(60):
            cycle(drv, peer)
        assert clears() == list(range(1, 9)) and drv.lifecycle is Lifecycle.INACTIVE


def test_configure_waits_for_heartbeats_as_well_as_estimates(seed):
    """Estimates alone do not make an axis configured: without heartbeats (an axis whose
    heartbeat is off) the set-up times out naming what it waited for."""

    class NoHeartbeats(ODriveScript):
        def __call__(self, msg, t):
            return [f for f in super().__call__(msg, t) if f.arbitration_id & 0x1F != HEARTBEAT]

    drv, _ = make(seed, NoHeartbeats(range(1, 9)), "odrive")
    with drv, pytest.raises(DriverTimeoutError, match="encoder estimates"):
        drv.configure(timeout=0.1)


def test_a_bus_refusing_every_frame_past_the_feedback_timeout_ends_the_writing(seed):
    """A refused send is a TX queue full for a moment or a link down for a blink: ridden
    through. Refused for longer than ``[drives] feedback_timeout`` (the drives as long without
    our torques as we would go without their feedback): an error of the write, saying how
    long; one frame through starts the count anew."""
    drv, peer = make(seed, ODriveScript(range(1, 9)), "odrive")
    with drv:
        drv.configure()
        cycle(drv, peer)
        limit = drv.config.feedback_timeout
        bus = drv.buses[0]

        def refuse(msg, timeout=None):
            raise can.CanError("Network is down")

        real = bus.send
        bus.send = refuse
        try:
            assert drv._write_cycle(peer.t, np.zeros(8)) is None  # the first refusals
            peer.t += 0.9 * limit
            assert drv._write_cycle(peer.t, np.zeros(8)) is None  # still within
            peer.t += 0.2 * limit
            err = drv._write_cycle(peer.t, np.zeros(8))
        finally:
            bus.send = real
        assert isinstance(err, DriverOperationError), err
        assert f"refused every frame for {1.1 * limit:.3f} s" in str(err)
        assert drv.stats.send_errors >= 24  # 8 torques a cycle, three cycles
        assert drv._write_cycle(peer.t, np.zeros(8)) is None  # frames through: reset
        bus.send = refuse
        try:
            peer.t += 0.5 * limit
            assert drv._write_cycle(peer.t, np.zeros(8)) is None  # a new run, counted anew
        finally:
            bus.send = real
