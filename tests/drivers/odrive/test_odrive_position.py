"""ODrive axes in position mode (``[drives] driver = "odrive"``, ``mode = "csp"``): the gains
from the model in ODrive's units, the set-up and cyclic frames written out here with struct
(ODrive's CAN Simple layouts, not the driver's), the following error the driver supervises,
the simulated axis's cascade against the closed-form response of the loop it claims to be,
and rowc with ODrive axes in lock-step: its demo and the 30 N jet."""

from __future__ import annotations

import contextlib
import math
import struct

import numpy as np
import pytest
from conftest import CONFIG
from test_drivers_frames import frame, make

from cdprctl.robot_file import load_robot
from drivers import DriveState, Lifecycle
from drivers.busload import bus_loads
from drivers.odrive.gains import axis_gains
from sim_backend.servo import servo_torque

TURN = 2 * math.pi
# CAN Simple command ids (docs.odriverobotics.com, "CAN Protocol")
HEARTBEAT, ENCODER, TORQUES = 0x01, 0x09, 0x1C
SET_AXIS_STATE, SET_CONTROLLER_MODE, SET_INPUT_POS, SET_INPUT_TORQUE = 0x07, 0x0B, 0x0C, 0x0E
SET_LIMITS, SET_POS_GAIN, SET_VEL_GAINS = 0x0F, 0x1A, 0x1B
POSITION_CONTROL, PASSTHROUGH, CLOSED_LOOP, IDLE = 3, 1, 8, 1
RTR = 0x100  # PositionAxes' mark of a remote frame


@pytest.fixture(scope="module")
def rowc_odrive():
    model = load_robot(CONFIG / "rowc_odrive.toml")
    assert model.drives.driver == "odrive" and model.drives.mode == "csp"
    return model


def test_the_gains_are_the_cia402_loop_in_odrive_units_a_fifth_of_the_rate_at_most(rowc_odrive):
    """kp = J ω², kd = 2 ζ J ω (ζ = 0.7) at min(position_loop_bandwidth, rate / 5), written
    as ODrive's cascade: vel_gain = kd (per turn/s), pos_gain = kp / kd; no integrator; the
    velocity limit twice the fastest cable speed a move asks for, the current limit the
    torque limit over the torque constant. Computed here from the file's numbers."""
    m, w = rowc_odrive, rowc_odrive.cables[0].winch
    J, zeta = 1.5e-4, 0.7
    assert w.rotor_inertia == J and w.torque_limit == 2.6
    for period, hz in ((1 / 100, 20.0), (1 / 250, 50.0), (1 / 500, 50.0)):
        g = axis_gains(m, 0, period)
        om = 2 * math.pi * hz
        assert g.bandwidth == pytest.approx(hz)
        assert g.vel_gain == pytest.approx(2 * zeta * J * om * TURN)  # N·m/(turn/s)
        assert g.pos_gain == pytest.approx(om / (2 * zeta))  # 1/s
        assert g.kp == pytest.approx(J * om**2)
        assert g.pos_gain * g.vel_gain / TURN == pytest.approx(J * om**2)  # N·m/rad
        assert g.vel_integrator_gain == 0.0
    b = np.linalg.norm(m.cables[0].attachment)
    cable_speed = m.control.max_velocity + m.control.max_angular_velocity * b  # m/s
    g = axis_gains(m, 0, 1 / 250)
    assert g.vel_limit == pytest.approx(2 * cable_speed * 5.0 / (TURN * 0.045))
    assert g.current_limit == pytest.approx(2.6 / 0.0827)


class PositionAxes:
    """Eight ODrive axes as a script: they keep what they are sent and, after the last axis's
    cyclic frame, stream each axis's encoder estimate (``pos`` turns, 0 turn/s), torques and
    heartbeat."""

    def __init__(self):
        self.pos = {n: 0.25 * n for n in range(1, 9)}
        self.state = {n: IDLE for n in range(1, 9)}
        self.got: dict[int, list[tuple[int, bytes]]] = {n: [] for n in range(1, 9)}
        self.torque = 0.5  # N·m: the torque estimate each axis reports

    def __call__(self, msg, t):
        node, cmd = msg.arbitration_id >> 5, msg.arbitration_id & 0x1F
        data = bytes(msg.data)
        self.got[node].append((cmd | (0x100 if msg.is_remote_frame else 0), data))
        if msg.is_remote_frame:
            self.rtr_dlc = msg.dlc  # the length it asks for
        if cmd == SET_AXIS_STATE:
            self.state[node] = struct.unpack("<I", data)[0]
        if cmd in (SET_INPUT_POS, SET_INPUT_TORQUE) and node == 8:
            out = []
            for n in self.pos:
                out.append(frame(n << 5 | ENCODER, struct.pack("<ff", self.pos[n], 0.0)))
                out.append(frame(n << 5 | TORQUES, struct.pack("<ff", 0.0, self.torque)))
                out.append(frame(n << 5 | HEARTBEAT, struct.pack("<IBBBx", 0, self.state[n], 0, 0)))
            return out
        return []

    def sent(self, node: int, cmd: int) -> list[bytes]:
        return [d for c, d in self.got[node] if c == cmd]


def test_the_set_up_sends_mode_gains_and_limits_and_each_cycle_a_set_input_pos(rowc_odrive):
    """Set-up: each axis gets position control with passthrough input, its gains and its
    limits (decoded here as float32s); each cycle one Set_Input_Pos per axis: the middle of
    the last two targets in turns, their rate as int16 × 0.001 turn/s, the torque as int16 ×
    0.001 N·m; a rate beyond the int16 saturates and counts as a clamped command."""
    axes = PositionAxes()
    drv, peer = make(rowc_odrive, axes, "odrive")
    g = axis_gains(rowc_odrive, 2, 0.002)  # make() runs the driver at 2 ms
    with drv:
        drv.configure()
        assert drv.lifecycle is Lifecycle.INACTIVE
        for n in range(1, 9):
            assert struct.unpack("<II", axes.sent(n, SET_CONTROLLER_MODE)[0]) == (
                POSITION_CONTROL, PASSTHROUGH)
        (pos_gain,) = struct.unpack("<f", axes.sent(3, SET_POS_GAIN)[0])
        vel_gain, integrator = struct.unpack("<ff", axes.sent(3, SET_VEL_GAINS)[0])
        vel_limit, current = struct.unpack("<ff", axes.sent(3, SET_LIMITS)[0])
        assert (pos_gain, vel_gain, integrator) == pytest.approx(
            (g.pos_gain, g.vel_gain, 0.0), rel=1e-6)
        assert (vel_limit, current) == pytest.approx((g.vel_limit, g.current_limit), rel=1e-6)
        assert not axes.sent(3, SET_INPUT_TORQUE)
        drv.read(peer.t)
        start = drv.states.position.copy()  # 0.25 n turns
        assert start[2] == pytest.approx(0.75 * TURN)
        targets = start + 0.01  # rad
        torques = np.linspace(-1.0, 1.0, 8)
        drv.write(peer.t, torques, force=True, targets=targets)
        peer.wait(0.002)
        assert drv.stats.clamped_commands == 0  # 796 counts: not saturated
        pos, vel, tau = struct.unpack("<fhh", axes.sent(3, SET_INPUT_POS)[-1])
        assert pos == pytest.approx((start[2] + 0.005) / TURN, rel=1e-6)  # the middle
        assert vel == round(0.01 / 0.002 / TURN / 0.001)  # 796 = 0.796 turn/s
        assert tau == round(torques[2] / 0.001)
        # the torques asked for by RTR just before each setpoint: the end of the last hold
        cycle = [c for c, _ in axes.got[3] if c in (SET_INPUT_POS, RTR | TORQUES)]
        assert cycle[-2:] == [RTR | TORQUES, SET_INPUT_POS] and axes.rtr_dlc == 8
        drv.read(peer.t)  # sampled as the first setpoint went out: the hold at rest
        assert drv.states.torque[2] == pytest.approx(0.5)
        drv.write(peer.t, torques, force=True, targets=targets + 0.01)
        peer.wait(0.002)
        drv.read(peer.t)  # the end of holding start + 5 mrad on the way to start + 10 mrad
        assert drv.states.torque[2] == pytest.approx(0.5 + g.ripple * g.kp * 0.005)
        clamped = drv.stats.clamped_commands
        drv.write(peer.t, torques, force=True, targets=targets + 1.0)  # 80 turn/s
        peer.wait(0.002)
        _, vel, _ = struct.unpack("<fhh", axes.sent(3, SET_INPUT_POS)[-1])
        assert vel == 32767 and drv.stats.clamped_commands - clamped == 8
        drv.write(peer.t, torques, force=True, targets=targets - 1.0)  # back: −160 turn/s
        peer.wait(0.002)
        _, vel, _ = struct.unpack("<fhh", axes.sent(3, SET_INPUT_POS)[-1])
        assert vel == -32767 and drv.stats.clamped_commands - clamped == 16


@contextlib.contextmanager
def active_axes(model, axes):
    """The ODrive driver on the scripted ``axes``, configured and enabled: (driver, peer)."""
    drv, peer = make(model, axes, "odrive")
    with drv:
        drv.configure()
        drv.read(peer.t)
        drv.activate()
        yield drv, peer


def hold_for_a_period(drv, peer, hold: np.ndarray) -> None:
    """One 2 ms cycle of the driver: the targets ``hold`` sent, the axes' answers read."""
    drv.write(peer.t, np.zeros(8), targets=hold)
    peer.wait(0.002)
    drv.read(peer.t)


def test_a_following_error_faults_only_when_it_persists(rowc_odrive):
    """The ODrive does not watch its following error; the driver does, as a CiA 402 drive
    would (0x8611): an axis off its setpoint beyond the window for one read rides through,
    for longer than [drives] following_error_timeout it faults and every axis is sent IDLE."""
    axes = PositionAxes()
    with active_axes(rowc_odrive, axes) as (drv, peer):
        assert drv.lifecycle is Lifecycle.ACTIVE
        hold = drv.states.position.copy()
        window = drv.following_window[4]
        assert window == pytest.approx(2.6 / axis_gains(rowc_odrive, 4, 0.002).kp)

        def period(off: float) -> None:
            axes.pos[5] = (hold[4] + off) / TURN
            hold_for_a_period(drv, peer, hold)

        period(0.0)
        period(1.5 * window)  # one read beyond: a transient
        period(0.0)
        assert drv.lifecycle is Lifecycle.ACTIVE, drv.error
        for _ in range(2):  # 2 ms, then 4 ms beyond: past the 3 ms time-out
            period(1.5 * window)
        assert drv.lifecycle is Lifecycle.ERROR
        assert drv.error.code == 0x8611 and "following error" in str(drv.error)
        # the line says how far (measured) against the window and time-out, in both units
        w = rowc_odrive.cables[4].winch
        mm = 1e3 * w.drum_radius / w.gear_ratio
        assert (f"{1.5 * window * mm:.2f} mm of cable ({1.5 * window:.4f} rad at the motor) off "
                f"its position target, beyond [drives] following_error_window = "
                f"{window * mm:.2f} mm ({window:.4f} rad) for more than following_error_timeout "
                f"= 3 ms") in str(drv.error)  # fmt: skip
        assert DriveState(drv.states.state[4]) is DriveState.FAULT
        drv.write(peer.t, np.zeros(8), targets=hold)  # the next cycle's frames
        peer.wait(0.002)
        assert all(struct.unpack("<I", axes.sent(n, SET_AXIS_STATE)[-1])[0] == IDLE
                   for n in range(1, 9))


def test_the_following_error_is_measured_from_the_path_not_the_setpoint(rowc_odrive):
    """The encoder estimate comes on the ODrive's timer, up to a period old, while the
    setpoint held is half a period ahead of the path: at 80 rad/s an estimate a period old is
    0.24 rad behind the setpoint, beyond rowc's 0.176 rad window, and on the path — it rides
    through; an axis that stops faults within five periods."""
    axes = PositionAxes()
    with active_axes(rowc_odrive, axes) as (drv, peer):
        assert drv.following_window[4] == pytest.approx(0.176, abs=0.001)
        targets = drv.states.position.copy()
        step = 80.0 * 0.002  # rad a period
        history = [targets[4]] * 2
        for _ in range(20):
            axes.pos[5] = history[-2] / TURN  # the target of the write before last
            targets[4] += step
            hold_for_a_period(drv, peer, targets)
            history.append(targets[4])
        assert drv.lifecycle is Lifecycle.ACTIVE, drv.error
        for _ in range(5):  # the axis stays where it was
            targets[4] += step
            hold_for_a_period(drv, peer, targets)
        assert drv.lifecycle is Lifecycle.ERROR and drv.error.code == 0x8611


class StuckAxes(PositionAxes):
    """As ``PositionAxes``, but node 5 never leaves closed loop: its Set_Axis_State frames
    are lost."""

    def __call__(self, msg, t):
        out = super().__call__(msg, t)
        if msg.arbitration_id == (5 << 5 | SET_AXIS_STATE):
            self.state[5] = CLOSED_LOOP
        return out


def test_after_a_fault_reset_the_following_error_is_timed_afresh(rowc_odrive):
    """A fault reset starts the following error's time from zero: an axis that stayed in
    closed loop (its IDLE lost) and is still off its target faults again once the reset's
    settling time is over, not a second later."""
    axes = StuckAxes()
    with active_axes(rowc_odrive, axes) as (drv, peer):
        hold = drv.states.position.copy()
        axes.pos[5] = (hold[4] + 1.5 * drv.following_window[4]) / TURN
        for _ in range(3):
            hold_for_a_period(drv, peer, hold)
        assert drv.lifecycle is Lifecycle.ERROR and drv.error.code == 0x8611
        drv.begin_recover(settle=0.02)
        assert drv.lifecycle is Lifecycle.INACTIVE
        for _ in range(20):  # 40 ms: the 20 ms settle and the 3 ms time-out, with margin
            hold_for_a_period(drv, peer, hold)
        assert drv.lifecycle is Lifecycle.ERROR and drv.error.code == 0x8611
        # without a settle: the first read after the reset is 2 ms beyond, within the 3 ms
        # time-out (a transient still); the second, 4 ms, is the fault
        drv.begin_recover(settle=0.0)
        hold_for_a_period(drv, peer, hold)
        assert drv.lifecycle is Lifecycle.INACTIVE
        hold_for_a_period(drv, peer, hold)
        assert drv.lifecycle is Lifecycle.ERROR and drv.error.code == 0x8611


def step_response(pos_gain, vel_gain, J, step, vel_limit=math.inf, limit=math.inf, ki=0.0,
                  load=0.0, seconds=0.2, dt=2e-4):
    """The simulated axis's cascade (rad units) on a bare rotor ``J``, a position step at
    t = 0, a constant ``load`` torque against it: (times, angles, integral)."""
    one = np.ones(1)
    servo = (np.array([step]), np.zeros(1), one.copy(), np.array([vel_gain]),
             np.array([limit]), np.zeros(1), np.array([math.inf]), np.array([math.inf]),
             np.zeros(1), np.array([pos_gain]), np.array([vel_limit]), np.array([ki]),
             np.zeros(1))  # fmt: skip
    theta = omega = 0.0
    out = []
    for _ in range(int(seconds / dt)):
        tau = servo_torque(servo, 0, theta, omega, 0.0, dt)
        omega += (tau - load) / J * dt  # semi-implicit Euler, as the plant
        theta += omega * dt
        out.append((theta, omega))
    return np.array(out), servo[12][0]


def test_the_simulated_cascade_is_the_loop_its_gains_say():
    """On a bare rotor the cascade with vel_gain = 2 ζ J ω and pos_gain = ω / 2ζ is the
    second-order loop ω, ζ: its step overshoots by exp(−π ζ / √(1 − ζ²)) (4.6 % at 0.7) and
    peaks at π / (ω √(1 − ζ²)); the velocity it asks for stops at vel_limit; a constant load
    leaves load / kp of error without the integrator and none with it."""
    J, zeta, om = 1.5e-4, 0.7, 2 * math.pi * 25.0
    kd, pg = 2 * zeta * J * om, om / (2 * zeta)
    x, _ = step_response(pg, kd, J, 0.01)
    theta = x[:, 0]
    overshoot = theta.max() / 0.01 - 1.0
    assert overshoot == pytest.approx(math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)),
                                      abs=0.004)
    t_peak = (np.argmax(theta) + 1) * 2e-4
    assert t_peak == pytest.approx(math.pi / (om * math.sqrt(1 - zeta**2)), rel=0.03)
    x, _ = step_response(pg, kd, J, 10.0, vel_limit=20.0, seconds=0.4)
    assert x[:, 1].max() == pytest.approx(20.0, rel=0.01)  # rad/s: at the limit, not beyond
    load = 0.05  # N·m
    x, _ = step_response(pg, kd, J, 0.0, load=load, seconds=0.3)
    assert x[-1, 0] == pytest.approx(-load / (kd * pg), rel=0.01)
    x, integral = step_response(pg, kd, J, 0.0, load=load, ki=0.2 * kd * om, seconds=1.0)
    assert abs(x[-1, 0]) < 1e-3 * load / (kd * pg) and integral == pytest.approx(load, rel=1e-3)
    # limited: the integral decays by 0.99 a step instead of winding up
    servo_out = step_response(pg, kd, J, 1.0, limit=0.01, ki=100.0, seconds=0.01)[1]
    assert abs(servo_out) < 0.01


@pytest.mark.parametrize("hz, rate", [(50.0, 250.0), (25.0, 250.0), (50.0, 500.0), (125.0, 250.0)])
def test_the_torque_at_the_end_of_a_hold_is_the_ripple_share_of_the_pull(hz, rate):
    """A bare rotor on the simulated cascade following a ramp through passthrough's staircase
    (the middle of each period's path held, its rate as velocity feed-forward), run until
    periodic: the torque of a hold's last 1/400 is ``−ripple · kp · v · T/2``, where a drive
    interpolating the ramp would apply none (``hold_ripple``'s closed form against the
    stepped firmware loop)."""
    from drivers.odrive.gains import hold_ripple

    J, zeta, v = 1.5e-4, 0.7, 30.0  # kg·m², rad/s
    om = 2 * math.pi * hz
    kp, kd = J * om**2, 2 * zeta * J * om
    T, n = 1.0 / rate, 400
    dt = T / n
    one = np.ones(1)
    servo = (np.zeros(1), np.array([v]), one.copy(), np.array([kd]), np.array([math.inf]),
             np.zeros(1), np.array([math.inf]), np.array([math.inf]), np.zeros(1),
             np.array([kp / kd]), np.array([math.inf]), np.zeros(1), np.zeros(1))  # fmt: skip
    theta, omega = 0.0, v
    for k in range(40):  # 40 periods: the rotor's transient (ζ ω = 220 rad/s) long gone
        servo[0][0] = v * (k + 0.5) * T  # the middle of the period's path
        for _ in range(n):
            tau = servo_torque(servo, 0, theta, omega, 0.0, dt)
            omega += tau / J * dt
            theta += omega * dt
    expected = -hold_ripple(J, kp, kd, T) * kp * v * T / 2
    assert tau == pytest.approx(expected, rel=2e-3)  # 0.05-0.08 % measured: the step's
    assert abs(tau) < 0.9 * kp * v * T / 2  # not all of the pull: the rotor takes a share


@pytest.mark.parametrize(
    ("hz", "rate", "zeta"), [(50.0, 250.0, 0.7), (25.0, 250.0, 1.0), (100.0, 500.0, 0.4)]
)
def test_the_ripple_is_the_periodic_solution_of_the_rotors_loop_to_nine_digits(hz, rate, zeta):
    """``hold_ripple``'s matrix exponential against scipy's ODE solver at tight tolerances:
    ``J ẍ + kd ẋ + kp x = kp (T/2 − τ)`` integrated period by period (per unit of v) until the
    state at the ends of two periods agrees to 1e-15; the ripple is then
    ``(kp T/2 + kp x(T) + kd ẋ(T)) / (kp T/2)`` (the firmware cascade's test above holds it
    only to its step's 0.1 %)."""
    from scipy.integrate import solve_ivp

    from drivers.odrive.gains import hold_ripple

    J = 1.5e-4  # kg·m²
    om = 2 * math.pi * hz
    kp, kd, T = J * om**2, 2 * zeta * J * om, 1.0 / rate

    def rotor(tau, y):
        return [y[1], (kp * (T / 2 - tau) - kd * y[1] - kp * y[0]) / J]

    y = np.zeros(2)
    for _ in range(400):
        end = solve_ivp(rotor, (0.0, T), y, method="DOP853", rtol=1e-13, atol=1e-22).y[:, -1]
        done = np.allclose(end, y, rtol=1e-12, atol=1e-20)
        y = end
        if done:
            break
    assert done
    pull = kp * T / 2
    expected = (pull + kp * y[0] + kd * y[1]) / pull
    assert hold_ripple(J, kp, kd, T) == pytest.approx(expected, rel=1e-9)


def test_the_simulated_axis_takes_its_limits_and_starts_where_it_stands(rowc_odrive):
    """The simulated ODrive: Set_Limits' current times the torque constant lowers its torque
    limit; entering closed loop it holds where the motor stands (no jump); in position control
    it answers RTRs for its torques and encoder estimates, and streams the latter; a speed beyond
    1.2 × vel_limit is its overspeed error (0x8000), the axis IDLE and braked."""
    from drivers.odrive import protocol as po
    from sim_backend.drives.odrive import ODriveAxis
    from sim_backend.plant import CdprPlant

    plant = CdprPlant(rowc_odrive)
    axis = ODriveAxis(3, 2, plant, 2.6, 0.1, torque_constant=0.0827)
    send = lambda cmd, data: axis.on_frame(cmd, data, False, 0.0)  # noqa: E731
    send(SET_CONTROLLER_MODE, struct.pack("<II", POSITION_CONTROL, PASSTHROUGH))
    send(SET_LIMITS, struct.pack("<ff", 10.0, 20.0))  # turn/s, A
    assert axis.torque_limit == pytest.approx(20.0 * 0.0827)
    send(SET_LIMITS, struct.pack("<ff", 10.0, 100.0))  # more than the motor gives
    assert axis.torque_limit == 2.6
    plant.theta[2] = 1.234
    send(SET_AXIS_STATE, struct.pack("<I", CLOSED_LOOP))
    assert axis.state is po.AxisState.CLOSED_LOOP_CONTROL
    assert plant.servo.target[2] == pytest.approx(1.234) and not plant.brake[2]
    # in position control its torques go out when asked for by RTR, not cyclically: the
    # driver asks as it sends the next setpoint
    assert {m.arbitration_id & 0x1F for m in axis.tick(0.0)} == {ENCODER, HEARTBEAT}
    plant.servo.applied[2] = 0.75
    (answer,) = axis.on_frame(TORQUES, b"", True, 0.0)
    assert answer.arbitration_id == 3 << 5 | TORQUES
    assert struct.unpack("<ff", answer.data)[1] == pytest.approx(0.75)
    (answer,) = axis.on_frame(ENCODER, b"", True, 0.0)
    assert struct.unpack("<ff", answer.data)[0] == pytest.approx(1.234 / TURN)
    plant.theta_dot[2] = 1.21 * 10.0 * TURN
    axis.tick(0.01)
    assert axis.error == 0x8000 and axis.state is po.AxisState.IDLE and plant.brake[2]


def test_the_simulated_axis_in_torque_control_gives_no_more_than_its_limit(rowc_odrive):
    """Set_Input_Torque beyond the axis's torque limit (a real ODrive clamps to its current
    limit): the motor gets the limit, either sign — a simulated drive that gave more would
    hide a controller asking for it."""
    from drivers.odrive import protocol as po
    from sim_backend.drives.odrive import ODriveAxis
    from sim_backend.plant import CdprPlant

    plant = CdprPlant(rowc_odrive)
    axis = ODriveAxis(3, 2, plant, 2.6, 0.1)
    send = lambda cmd, data: axis.on_frame(cmd, data, False, 0.0)  # noqa: E731
    send(SET_CONTROLLER_MODE, struct.pack("<II", po.CONTROL_MODE_TORQUE, PASSTHROUGH))
    send(SET_AXIS_STATE, struct.pack("<I", CLOSED_LOOP))
    for asked, given in ((10.0, 2.6), (-10.0, -2.6), (1.5, 1.5)):  # N·m
        send(SET_INPUT_TORQUE, struct.pack("<f", asked))
        assert plant.motor_torque[2] == pytest.approx(given)


def test_the_bus_load_of_four_axes_in_position_mode():
    """A cycle of four axes: Set_Input_Pos, encoder estimates and torques, 8 bytes each, 135
    bits with worst-case stuffing (Davis et al. 2007, eq. (1)), and the RTR for the torques, no
    data, 55 bits: 1,840 bits; with five 8-byte heartbeats at 10 Hz, 46.7 % of 1 Mbit/s at
    250 Hz and 92.7 % at 500 Hz."""
    model = load_robot(CONFIG / "rowc_odrive.toml")
    bits = 8 * 8 + 47 + (34 + 64 - 1) // 4
    rtr = 47 + (34 - 1) // 4
    assert (bits, rtr) == (135, 55)
    for rate, load in ((250.0, 0.467), (500.0, 0.927)):
        for bl in bus_loads(model.drives, rate):
            assert bl.bits_per_cycle == 12 * bits + 4 * rtr
            assert bl.load == pytest.approx(((12 * bits + 4 * rtr) * rate + 5 * bits * 10) / 1e6)
            assert bl.load == pytest.approx(load, abs=0.001)


def test_rowc_with_odrive_axes_runs_its_demo_and_holds_the_jet(rowc_odrive):
    """Lock-step at 250 Hz: the demo's moves without a fault, the simulated platform within
    0.06 mm of the reference (0.030 measured; CiA 402 drives 0.041: docs/control.md; 1.2
    with the torque less all of the loop's pull), then the 30 N jet ramped in over 1 s: its
    transient within 15 mm and the deflection gone."""
    from cdprctl.daemon.scripts import demo_targets
    from cdprctl.experiments.closed_loop import ClosedLoop, ramped_force

    m = rowc_odrive
    a, b = demo_targets(m)
    with ClosedLoop(m) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(0.5)
        c = cl.controller
        for p in (a, m.home.position, b, m.home.position):
            cl.command("move", pose=np.concatenate([p, m.home.rpy]))
            cl.run(3.0)
            assert c.data.state.value == "enabled", c.data.fault_reason
        arr = cl.arrays()
        err = np.linalg.norm(arr["p_true"] - arr["p_des"][:, :3], axis=1)
        assert err.max() < 6e-5, err.max()
        y0, t0 = cl.plant.position[1], cl.net.time
        cl.run(5.0, each=ramped_force(t0, 30.0))
        arr = cl.arrays()
        dy = arr["p_true"][arr["t"] >= t0, 1] - y0
        assert c.data.state.value == "enabled", c.data.fault_reason
        assert np.max(np.abs(dy)) < 0.015 and abs(dy[-1]) < 0.001


def test_an_odrive_robot_file_needs_what_its_frames_can_carry(tmp_path):
    """Position mode with ODrive axes: a torque limit beyond Set_Input_Pos's int16 × 0.001
    N·m is refused, and the torque constant is required (the current limit); torque mode
    needs neither."""
    from cdprctl.model import ConfigError

    text = (CONFIG / "rowc.toml").read_text().replace("torque_limit = 2.6", "torque_limit = 40.0")
    text = text.replace('mode = "csp"', 'mode = "csp"\ndriver = "odrive"\ntorque_constant = 0.5')
    path = tmp_path / "big.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_robot(path)
    assert "winch.torque_limit = 40 N·m must be <= 32.767" in str(e.value)
    assert "int16 × 0.001 N·m" in str(e.value)
    path.write_text(text.replace("torque_constant = 0.5\n", ""))
    with pytest.raises(ConfigError) as e:
        load_robot(path)
    assert "drives.torque_constant is missing" in str(e.value)
    for kt, amps in (("100", "0.026 A"), ("0.01", "260 A")):  # the KV typed; too weak a motor
        path.write_text(text.replace("torque_limit = 40.0", "torque_limit = 2.6")
                        .replace("torque_constant = 0.5", f"torque_constant = {kt}"))
        with pytest.raises(ConfigError) as e:
            load_robot(path)
        assert f"gives a current limit of {amps}" in str(e.value) and "[1, 120] A" in str(e.value)
    path.write_text(text.replace('mode = "csp"', 'mode = "cst"'))
    assert load_robot(path).drives.mode == "cst"  # torque mode carries it as a float32


def test_the_daemon_says_what_it_sent_the_axes(capsys):
    """`cdprctl run` prints the gains and limits as sent, in ODrive's units (what odrivetool
    shows), and the following error it supervises, in rad and mm of cable."""
    from cdprctl.cli import main

    config = str(CONFIG / "rowc_odrive.toml")
    assert main(["run", "--config", config, "--sim", "--no-demo", "--no-realtime",
                 "--duration", "0.2"]) == 0  # fmt: skip
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("gains"))
    assert "the loop at 50 Hz" in line and "pos_gain 224.4 (turn/s)/turn" in line
    assert "vel_gain 0.4145 N·m/(turn/s), vel_integrator_gain 0" in line
    assert "vel_limit 12.2 turn/s, current limit 31.4 A" in line
    assert "beyond 0.176 rad (1.58 mm of cable) for 3 ms" in line


def test_node_ids_are_the_protocols_own(tmp_path):
    """ODrive axes take CAN Simple's 6-bit node ids, 0 to 62 (0x3F is an unaddressed
    ODrive's); CiA 402 drives CANopen's, 1 to 127 (0 addresses every node)."""
    from cdprctl.model import ConfigError

    odrive = (CONFIG / "rowc_odrive.toml").read_text()
    rowc = (CONFIG / "rowc.toml").read_text()
    path = tmp_path / "rowc.toml"
    path.write_text(rowc.replace("node_ids = [1, 2, 3, 4]", "node_ids = [0, 2, 3, 4]"))
    with pytest.raises(ConfigError) as e:
        load_robot(path)
    assert "node_ids = 0 must be a CANopen node id in [1, 127]" in str(e.value)
    for ids, ok in (("[0, 2, 3, 4]", True), ("[63, 2, 3, 4]", False)):
        path.write_text(rowc.replace("node_ids = [1, 2, 3, 4]", f"node_ids = {ids}"))
        (tmp_path / "od.toml").write_text(odrive)
        if ok:
            assert load_robot(tmp_path / "od.toml").drives.buses[0].node_ids[0] == 0
        else:
            with pytest.raises(ConfigError) as e:
                load_robot(tmp_path / "od.toml")
            assert "node_ids = 63 must be an ODrive axis's CAN Simple node id" in str(e.value)
            assert "[0, 62]" in str(e.value)
