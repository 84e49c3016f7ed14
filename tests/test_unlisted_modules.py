"""Rules of modules outside the mutation targets, each against a reference written out here:
bugs independent checks planted there (one at a time, in a scratch copy) that no test
caught — the wrench the cables must hold, the soft limits' inertial load and their batch
shortcut, the telemetry's fault kind, the wrench observer's bandwidth, the estimator's
sample instants, the distribution's tension margin, a platform-frame jog, the pose loop's
anti-windup. Each test fails on its planted bug. (The second check's other finds are held in
their modules' own test files: rotation, trajectory, config, busload, tda, estop, the
simulated ODrive.)"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.control.data import ControlData
from cdprctl.control.states import FaultKind
from cdprctl.core.rotation import exp_so3
from cdprctl.motion.limits import SoftLimits
from cdprctl.robot_file import load_robot
from cdprctl.tda.workspace import hold_wrench
from cdprctl.telemetry.snapshot import SharedSnapshot, controller_values
from cdprctl.telemetry.zenoh.schema import state_payload


def weight_wrench_by_hand(model, R):
    """Gravity on the platform at its COM, as a wrench at P in the base frame."""
    f = model.platform.mass * np.asarray(model.gravity, dtype=float)
    return np.concatenate([f, np.cross(R @ np.asarray(model.platform.com, dtype=float), f)])


@pytest.mark.parametrize("robot_file", ["rowc.toml", "caroca.toml", "seed000.toml"])
def test_the_cables_hold_minus_the_weight_and_the_known_external_wrench(robot_file):
    model = load_robot(CONFIG / robot_file)
    rng = np.random.default_rng(46)
    for _ in range(5):
        R = exp_so3(rng.normal(scale=0.2, size=3)) @ model.home.rotation
        ext = rng.normal(scale=20.0, size=6)
        expected = -(weight_wrench_by_hand(model, R) + ext)  # W t + w_g + w_e = 0
        np.testing.assert_allclose(hold_wrench(model, R, ext), expected, rtol=1e-12, atol=1e-9)


def test_the_soft_limits_add_the_motions_inertial_load():
    """What the cables must exert while accelerating: the holding wrench plus m·a and R I Rᵀ α
    (as SoftLimits writes it); an upward acceleration of a hanging load asks for m·a more."""
    model = load_robot(CONFIG / "rowc.toml")
    lim = SoftLimits(model)
    rng = np.random.default_rng(47)
    R = np.array([exp_so3(rng.normal(scale=0.1, size=3)) @ model.home.rotation for _ in range(4)])
    acc = rng.normal(scale=2.0, size=(4, 6))
    got = lim.wrenches(R, acc)
    inertia = np.asarray(model.platform.inertia, dtype=float)
    for k in range(4):
        inertial = np.concatenate([model.platform.mass * acc[k, :3],
                                   R[k] @ inertia @ R[k].T @ acc[k, 3:]])  # fmt: skip
        expected = hold_wrench(model, R[k], model.control.external_wrench) + inertial
        np.testing.assert_allclose(got[k], expected, rtol=1e-12, atol=1e-9)
    up = np.zeros((1, 6))
    up[0, 2] = 3.0
    lifted = lim.wrenches(R[:1], up)[0, 2] - lim.wrenches(R[:1], None)[0, 2]
    assert lifted == pytest.approx(3.0 * model.platform.mass)


def test_telemetry_reports_no_fault_kind_until_there_is_one():
    model = load_robot(CONFIG / "rowc.toml")
    d = ControlData(model.n_cables, 0)
    d.tda_method = model.control.tda_method  # as the distribution sets it
    snap = SharedSnapshot(model.n_cables)
    try:
        names = [c.name for c in model.cables]
        snap.write(controller_values(d))
        assert state_payload(snap.read(), names, "")["fault_kind"] == ""
        for kind in (next(iter(FaultKind)), FaultKind.TRACKING):
            d.fault_kind = kind
            snap.write(controller_values(d))
            assert state_payload(snap.read(), names, "")["fault_kind"] == kind.value
        # the safety state: the chain open only in the e-stop, the brakes released only while
        # the drives are enabled, the stop category through the snapshot (-1: none)
        from cdprctl.control.states import State

        for state, chain, brakes in [(State.ESTOP, "open", "closed"),
                                     (State.MOVING, "closed", "released"),
                                     (State.STOPPING, "closed", "released"),
                                     (State.FAULT, "closed", "closed"),
                                     (State.READY, "closed", "closed")]:  # fmt: skip
            for category in (-1, 0, 1, 2):
                d.state, d.stop_category = state, category
                snap.write(controller_values(d))
                safety = state_payload(snap.read(), names, "", brake_test={"x": 1})["safety"]
                assert (safety["chain"], safety["brakes"]) == (chain, brakes), state
                assert safety["stop_category"] == (None if category < 0 else category)
                assert safety["tripped"] == "tracking" and safety["brake_test"] == {"x": 1}
    finally:
        snap.close()


def test_the_wrench_observer_is_a_first_order_lag_of_its_bandwidth():
    """The platform at rest on tensions that balance its weight and a constant external
    wrench: the observer's estimate rises as w_e (1 − e^(−2π f t)) (De Luca's momentum
    observer, r' = L (w_e − r), L = 2π·observer_bandwidth rad/s)."""
    import dataclasses

    from conftest import in_torque_mode

    from cdprctl.control.cycle.cycle_io import pose_args
    from cdprctl.control.cycle.estimator import Estimator
    from cdprctl.control.cycle.observer import WrenchObserver
    from cdprctl.control.cycle.torques import WinchTorques
    from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics

    base = in_torque_mode(load_robot(CONFIG / "rowc.toml"))
    f_hz = 2.0
    model = dataclasses.replace(
        base, control=dataclasses.replace(base.control, observer_bandwidth=f_hz)
    )
    est = Estimator(model)
    est.reset(model.home.position, model.home.rotation)
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    est.kin.W[:] = kin.W  # the estimate at home, at rest
    est.kin.WT[:] = kin.WT
    wt = WinchTorques(model)
    w_e = np.array([4.0, 30.0, -6.0, 0.5, -0.3, 0.2])  # N, N·m at P
    t_a = np.linalg.lstsq(kin.W, -(weight_wrench_by_hand(model, model.home.rotation) + w_e),
                          rcond=None)[0]  # fmt: skip
    torque = wt.r * t_a  # at rest: no friction, no rotor term
    d = ControlData(model.n_cables, 0)
    obs = WrenchObserver(model, d)
    assert obs.enabled
    obs.reset(pose_args(est))
    dt, zeros = model.control.period, np.zeros(model.n_cables)
    tau = 1.0 / (2.0 * np.pi * f_hz)
    seen = {}
    for k in range(round(5 * tau / dt) + 2):
        obs.update(k * dt, torque, zeros, np.zeros(6), pose_args(est), est.kin)
        seen[k] = d.ext_estimate.copy()
    k1 = round(tau / dt) + 1  # the first update only starts the integral
    # the discrete steps at 500 Hz (L dt = 0.025) land within 5 % of the continuous lag: a
    # bandwidth taken as rad/s instead of Hz would be at 15 % of w_e there
    np.testing.assert_allclose(seen[k1], w_e * (1 - np.exp(-1.0)), rtol=0.05, atol=0.05)
    np.testing.assert_allclose(seen[max(seen)], w_e * (1 - np.exp(-5.0)), rtol=0.01, atol=0.05)


def test_the_estimators_velocity_takes_each_sample_at_its_own_instant():
    """A platform moving at 0.1 m/s along x, read every 2 ms with feedback 0 and 1 ms old in
    turn (the drives' samples are their SYNC's, not the read's): each sample is placed at its
    own instant (read time less its age), so the filtered velocity is the motion's, without
    the beat an instant off by the age would add."""
    from cdprctl.control.cycle.estimator import Estimator
    from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics

    model = load_robot(CONFIG / "rowc.toml")
    est = Estimator(model)
    p0, R = np.asarray(model.home.position, dtype=float), model.home.rotation
    est.reset(p0, R)
    kin = KinematicsData(model)
    m, speed, zeros = model.n_cables, 0.1, np.zeros(model.n_cables)
    rate = np.zeros(m)
    vx = []
    for k in range(400):
        t_read = 0.002 * k
        age = np.full(m, 0.001 * (k % 2))
        at = t_read - age[0]  # where the platform was when the drives sampled
        inverse_kinematics(model, kin, p0 + np.array([speed * at, 0.0, 0.0]), R)
        theta = (est.l_zero - kin.length) / est.drum_ratio  # no tension: no stretch
        est.update(t_read, theta, zeros, rate, age)
        vx.append(float(est.velocity[0]))
    tail = np.array(vx[200:])
    assert np.abs(tail - speed).max() < 0.002 * speed, (tail.min(), tail.max())


def _controller_at_home(model):
    from conftest import FakeDrives

    from cdprctl.control.cycle.controller import Controller
    from drivers.vocabulary import Lifecycle

    c = Controller(model, FakeDrives(model.n_cables, Lifecycle.INACTIVE))
    c.estimator.update(0.0, np.zeros(model.n_cables), model.tension_min.copy())
    c.data.wrench[:] = c.pose.gravity_hold(c.at.rotation, c.data.ext_total)
    return c


def test_the_distribution_keeps_its_tension_margin_from_both_limits():
    """``[control] tension_margin`` N from each limit: a wrench that pushes the tensions to
    their bounds gets tensions inside [t_min + margin, t_max − margin], not beyond."""
    import dataclasses

    base = load_robot(CONFIG / "rowc.toml")
    margin = 12.0
    model = dataclasses.replace(
        base, control=dataclasses.replace(base.control, tension_margin=margin)
    )
    c = _controller_at_home(model)
    lo, hi = model.tension_min + margin, model.tension_max - margin
    c.distribution.distribute(c.at)  # the holding tensions, feasible: held when a wrench is not
    rng = np.random.default_rng(48)
    inside = 0
    for _ in range(40):
        # a feedback wrench beyond what the cables give: saturated onto the feasible set's
        # edge, where a tension sits at its bound
        c.data.feedback_wrench[:] = rng.normal(scale=400.0, size=6)
        hold = c.pose.gravity_hold(c.at.rotation, c.data.ext_total)
        c.data.wrench[:] = hold + c.data.feedback_wrench
        c.data.tensions[:] = c.data.hold_tensions  # no rate limit in the way of the bounds
        out = c.distribution.distribute(c.at)
        t = c.data.tensions
        assert np.all(t >= lo - 1e-6) and np.all(t <= hi + 1e-6), (out.status, t)
        inside += bool(np.any(t <= lo + 0.5) or np.any(t >= hi - 0.5))
    assert inside > 5  # the bounds were met, not just stayed away from


@pytest.mark.parametrize(
    "change", [[0, 0, 0, 0, 0, 1.0], [0.5, 0, 0.1, 0, 0, 0]], ids=["turn", "move"]
)
def test_a_batch_of_samples_is_checked_as_each_sample_alone(change):
    """``SoftLimits.check`` of a batch (its one-orientation shortcut for a translation at rest)
    gives each sample the margin it has checked alone: a turn on the spot, and a translation."""
    model = load_robot(CONFIG / "rowc.toml")
    lim = SoftLimits(model)
    home = np.r_[model.home.position, np.zeros(3)]
    samples = home + np.linspace(0.0, 0.6, 7)[:, None] * np.array(change)
    batch, _ = lim.check(samples)
    alone = np.array([lim.check(s[None])[0][0] for s in samples])
    np.testing.assert_allclose(batch, alone, rtol=1e-12)
    assert np.ptp(alone) > 1.0  # N: the samples' margins differ


def test_a_platform_frame_jog_goes_along_the_platforms_axes():
    """A jog in the platform frame from a pose turned 0.15 rad about z: +x of the platform is
    (cos 0.15, sin 0.15, 0) in the base frame."""
    from cdprctl.control.command_types import Command, CommandKind
    from cdprctl.control.intake.jog import Jog
    from cdprctl.motion.trajectory import Trajectory

    model = load_robot(CONFIG / "rowc.toml")
    tr = Trajectory(model, 0.004)
    tr.reset(np.r_[model.home.position, 0.0, 0.0, 0.15])
    jog = Jog(model, ControlData(model.n_cables, 0))
    cmd = Command(CommandKind("jog"), velocity=np.array([0.1, 0, 0, 0, 0, 0]), frame="platform")
    plan = jog.plan(cmd, tr, SoftLimits(model))
    assert plan is not None and plan.target is not None
    d = plan.target[:3] - tr.position[:3]
    np.testing.assert_allclose(d / np.linalg.norm(d), [np.cos(0.15), np.sin(0.15), 0.0], atol=1e-9)


def test_the_pose_loops_integral_term_is_bounded_at_ten_per_second_squared():
    """Torque mode (the pose loop on): each axis's integral is clamped where its term
    ki·∫e reaches 10 m/s² (rad/s²) — the anti-windup wrench.py states, whatever the
    bandwidth; position mode: the loop off, nothing to wind up."""
    from conftest import in_torque_mode

    model = in_torque_mode(load_robot(CONFIG / "rowc.toml"))
    pose = _controller_at_home(model).pose
    assert len(set(pose.bandwidth.tolist())) > 1  # rowc's axes differ (y at 0.6 Hz)
    np.testing.assert_allclose(pose.ki * pose.integral_limit, 10.0, rtol=1e-12)
    off = _controller_at_home(load_robot(CONFIG / "rowc.toml")).pose
    assert not off.ki.any() and not off.integral_limit.any()
