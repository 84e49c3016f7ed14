"""The simulated robot's physics against analytic results and the foundation's stiffness."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.core.rotation import exp_so3, log_so3
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.geometry.stiffness import stiffness_matrix
from cdprctl.robot_file import load_robot
from sim_backend.plant import CdprPlant, PlantOptions, equilibrium_tensions


@pytest.fixture(scope="module", params=["rowc.toml", "seed000.toml"])
def model(request):
    return load_robot(CONFIG / request.param)


def kinematics_at(plant: CdprPlant) -> KinematicsData:
    """The inverse kinematics at the plant's pose now (its lengths, W): what its next physics
    step starts from, computed here rather than read from the plant."""
    kin = KinematicsData(plant.model)
    inverse_kinematics(plant.model, kin, plant.position.copy(), plant.R.copy())
    return kin


def test_gravity_equilibrium_with_tda_tensions(model):
    plant = CdprPlant(model)
    t0 = plant.tension.copy()
    plant.step(1.0)  # brakes closed, no external force
    np.testing.assert_allclose(plant.position, model.home.position, atol=1e-9)
    np.testing.assert_allclose(plant.tension, t0, rtol=1e-9, atol=1e-9)
    # and those tensions are the TDA's (the controller's start point)
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    np.testing.assert_allclose(t0, equilibrium_tensions(model, kin))


def test_static_deflection_equals_K_inverse_dw(model):
    """Brakes closed: a small external wrench displaces the platform by K⁻¹ δw
    (Picard et al. 2020, eq. (3)-(4); K from cdprctl.geometry.stiffness)."""
    plant = CdprPlant(model, PlantOptions(damping_ratio=0.3))
    dw = np.array([0.0, 2.0, -1.0, 0.05, 0.0, 0.02])  # N, N·m: small
    # a slow ramp (quasi-static: the transverse modes, barely damped by the cables, stay
    # unexcited), then a hold
    for s in np.linspace(0.0, 1.0, 401)[1:]:
        plant.ext_force[:] = s * dw[:3]
        plant.ext_moment[:] = s * dw[3:]
        plant.step(0.01)
    plant.step(2.0)
    # the suspended robot's pendulum modes (periods of seconds) are barely damped by the
    # cables: average the pose over 16 s
    samples = []
    for _ in range(320):
        plant.step(0.05)
        samples.append(
            np.concatenate(
                [plant.position - model.home.position, log_so3(plant.R @ model.home.rotation.T)]
            )
        )
    got = np.mean(samples, axis=0)
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    l0 = plant.unstretched_length()
    k = np.array(
        [
            1.0 / (1.0 / (x.stiffness or x.youngs_modulus * x.cross_section / l0[i]))
            for i, x in enumerate(model.cables)
        ]
    )
    K = stiffness_matrix(model, kin, equilibrium_tensions(model, kin), k)
    expected = np.linalg.solve(K, dw)
    np.testing.assert_allclose(got, expected, rtol=0.02, atol=2e-3 * np.abs(expected).max())


def test_free_winch_friction_run_down():
    """A winch with no cable load: J ω̇ = −b ω − τ_c (ω >> ω_ε), so
    ω(t) = (ω0 + τ_c/b) e^(−b t/J) − τ_c/b."""
    model = load_robot(CONFIG / "rowc.toml")
    plant = CdprPlant(model, PlantOptions(coulomb_velocity=1e-3))
    plant.cable_cut[0] = True
    plant.brake[0] = False
    plant.theta_dot[0] = 200.0
    w = model.cables[0].winch
    J, b, tc = w.rotor_inertia, w.viscous_friction, w.coulomb_friction
    t_stop = J / b * math.log((200.0 + tc / b) / (tc / b))
    for t in (0.05, 0.15, 0.3):
        plant.step(t - plant.time)
        expected = (200.0 + tc / b) * math.exp(-b * t / J) - tc / b
        assert plant.theta_dot[0] == pytest.approx(expected, rel=2e-3)
    plant.step(t_stop + 0.2 - plant.time)  # Coulomb friction holds it once stopped, up to
    # the chatter of one step's friction impulse (τ_c/J · dt)
    assert abs(plant.theta_dot[0]) <= tc / J * plant.opt.physics_dt + 1e-9


def test_slack_cable_carries_no_tension(model):
    plant = CdprPlant(model)
    plant.theta[3] -= 0.5 / plant.drum_ratio[3]  # pay out 0.5 m: far slacker than any stretch
    plant.step(0.001)
    assert plant.tension[3] == 0.0
    assert np.all(plant.tension[[0, 1, 2, 4, 5, 6, 7]] > 0)


def test_cut_cable_and_energy_drift_bounded():
    """No damping, no friction, brakes closed, the platform set swinging: the symplectic
    integrator keeps the total energy within 0.5 % of the motion's energy over 10 s."""
    model = load_robot(CONFIG / "seed000.toml")
    plant = CdprPlant(model, PlantOptions(damping_ratio=0.0))
    plant.damping[:] = 0.0
    plant.v[:] = [0.05, -0.03, 0.02]
    plant.w[:] = [0.01, 0.0, -0.02]
    e0 = plant.energy()
    swing = 0.5 * model.platform.mass * 0.05**2
    worst = 0.0
    for _ in range(100):
        plant.step(0.1)
        worst = max(worst, abs(plant.energy() - e0))
    assert worst < 0.005 * swing


def test_pulley_friction_capstan_factor():
    """A released winch paying out under tension sees t·exp(−μβ) through its pulley: its
    first acceleration is ((r/G) t e^(−μβ) − friction)/J."""
    model = load_robot(CONFIG / "caroca_pulleys.toml")
    acc = {}
    for mu in (0.0, 0.2):
        plant = CdprPlant(model, PlantOptions(pulley_friction=mu, coulomb_velocity=1e-6))
        plant.theta_dot[0] = -1e-3  # already paying out (direction of the friction)
        plant.brake[0] = False
        t = plant.tension[0]
        beta = plant.kin.wrap_angle[0]
        plant.step(1e-6)
        acc[mu] = (plant.theta_dot[0] + 1e-3) / 1e-6
    w = model.cables[0].winch
    r = w.drum_radius / w.gear_ratio
    J, tc, b = w.rotor_inertia, w.coulomb_friction, w.viscous_friction
    for mu in acc:
        expected = (-r * t * math.exp(-mu * beta) + tc - b * 1e-3 * -1) / J
        assert acc[mu] == pytest.approx(expected, rel=1e-3)
    assert abs(acc[0.2]) < abs(acc[0.0])


def test_the_drives_torque_does_not_depend_on_where_a_step_is_split():
    """A drive's position loop on a target ramping at 20 rad/s: the torque it applies (its
    torque actual) after 2 ms of physics in one step or as 1.9 + 0.1 ms is the same within
    0.001 N·m. With the target moved on before the loop was taken, the torque carried
    kp · rate · dt of the last step: a short one read 0.037 N·m less (7 N of apparent tension
    on seed000), and in lock-step with the last 5 % of each period split off seed000 tracked
    18.6 mm instead of 1.9 (the frames split the physics wherever they arrive)."""
    model = load_robot(CONFIG / "seed000.toml")
    w = model.cables[0].winch
    kp, kd = model.drives.position_gains(w.rotor_inertia)
    assert kp * 20.0 * 1e-4 > 0.035  # N·m: what the old law's short step left out

    def on_a_ramp() -> CdprPlant:
        plant = CdprPlant(model)
        plant.step(0.002)
        s = plant.servo
        plant.brake[:] = False
        s.kp[:], s.kd[:], s.limit[:], s.window[:] = kp, kd, w.torque_limit, np.inf
        s.target[:] = plant.theta
        plant.motor_torque[:] = plant.tension * w.drum_radius / w.gear_ratio
        s.rate[:] = 0.0
        s.rate[0] = 20.0  # rad/s
        for _ in range(50):
            plant.step(0.002)
        return plant

    whole, split = on_a_ramp(), on_a_ramp()
    whole.step(0.002)
    split.step(0.0019)
    split.step(0.0001)
    assert abs(whole.theta[0] - split.theta[0]) < 1e-6  # rad: the same motion
    assert abs(whole.servo.applied[0] - split.servo.applied[0]) < 1e-3  # N·m


@pytest.mark.parametrize("slip", [60.0, 200.0, 1000.0])
def test_a_cable_paying_out_fast_never_pushes(slip):
    """A taut cable whose brake slips (rad/s, paying out): its stretch still positive, the
    damping term ``c ė`` of the cable law goes negative faster than ``k e`` shrinks — the cable
    goes slack at zero tension, it never pushes the platform. Each step's force is checked
    for a push; the rule must have acted (stretched, yet no force) for the test to count."""
    model = load_robot(CONFIG / "rowc.toml")
    plant = CdprPlant(model)
    i = 3
    plant.brake_slip[i] = slip
    dt = plant.opt.physics_dt
    seen_clamped = False
    kin = KinematicsData(model)
    for _ in range(200):
        inverse_kinematics(model, kin, plant.position, plant.R)
        taut = kin.length[i] > plant.unstretched_length()[i]  # stretched as the step starts
        plant.step(dt)  # one physics step: its tension is the law at the step's start
        assert np.all(plant.tension >= 0.0), plant.tension
        seen_clamped |= bool(taut and plant.tension[i] == 0.0)
    assert seen_clamped  # the rule acted: taut (stretched) yet no force


def test_an_external_force_at_p_on_a_free_platform_is_newton_euler_about_the_com():
    """Every cable cut, the platform at rest (cogiro: its COM off P on every axis): one
    physics step of dt under a force F at P gives v = dt (F/m + g) and, about the COM,
    I_w ω̇ = (P − COM) × F — Newton-Euler written out here, not through the kernel."""
    model = load_robot(CONFIG / "cogiro.toml")
    plant = CdprPlant(model)
    plant.cable_cut[:] = True
    force = np.array([30.0, -20.0, 10.0])
    plant.ext_force[:] = force
    R, dt = plant.R.copy(), plant.opt.physics_dt
    lever = -(R @ np.array(model.platform.com))  # P − COM, base frame
    assert np.all(np.abs(lever) > 0.01)
    plant.step(dt)
    m, inertia = model.platform.mass, R @ np.array(model.platform.inertia) @ R.T
    np.testing.assert_allclose(plant.v, dt * (force / m + np.array(model.gravity)), rtol=1e-12)
    np.testing.assert_allclose(plant.w, dt * np.linalg.solve(inertia, np.cross(lever, force)),
                               rtol=1e-9)  # fmt: skip


def test_cable_damping_acts_on_the_cable_rates_of_the_platforms_twist():
    """A platform moving and turning (cogiro, COM off P): each cable's tension differs from
    the platform at rest by its damping times its length's rate — the rate by central
    differences of the inverse kinematics along P's velocity v − ω × (R c) and ω."""
    model = load_robot(CONFIG / "cogiro.toml")
    still, moving = CdprPlant(model), CdprPlant(model)
    v, w = np.array([0.05, -0.03, 0.04]), np.array([0.02, -0.01, 0.03])
    moving.v[:], moving.w[:] = v, w
    R, com_pos = moving.R.copy(), moving.com_pos.copy()
    com = R @ np.array(model.platform.com)
    p, v_p = com_pos - com, v - np.cross(w, com)
    kin, h = KinematicsData(model), 1e-6

    def lengths(s: float) -> np.ndarray:
        inverse_kinematics(model, kin, p + s * h * v_p, exp_so3(s * h * w) @ R)
        return kin.length.copy()

    rate = (lengths(1.0) - lengths(-1.0)) / (2 * h)
    for plant in (still, moving):
        plant.step(plant.opt.physics_dt)
    assert np.all(still.tension > 0) and np.all(np.abs(rate) > 1e-3)
    np.testing.assert_allclose(moving.tension - still.tension, moving.damping * rate,
                               rtol=1e-6)  # fmt: skip


def test_a_slack_cable_takes_the_tension_off_its_jaw_whichever_jaw():
    """seed000_grippers: jaws on cables 1 and 8; cable 8 cut, its jaw's jB carries nothing
    from the next step on, the other jaw its weight."""
    plant = CdprPlant(load_robot(CONFIG / "seed000_grippers.toml"))
    assert np.all(plant.jb_tension > 50.0)
    plant.cable_cut[7] = True
    plant.step(plant.opt.physics_dt)
    assert plant.jb_tension[1] == 0.0
    assert plant.jb_tension[0] == pytest.approx(10.2 * 9.8, rel=1e-3)


def test_a_spinning_free_platform_follows_eulers_equations():
    """Every cable cut, no force but gravity (at the COM: no moment), the platform spinning
    about no principal axis: one physics step gives ω + dt I_w⁻¹ (−ω × I_w ω), Euler's
    equations in the base frame written out here."""
    model = load_robot(CONFIG / "cogiro.toml")
    plant = CdprPlant(model)
    plant.cable_cut[:] = True
    w = np.array([0.7, -1.1, 0.9])  # rad/s
    plant.w[:] = w
    R, dt = plant.R.copy(), plant.opt.physics_dt
    inertia = R @ np.array(model.platform.inertia) @ R.T
    gyro = -np.cross(w, inertia @ w)
    assert np.all(np.abs(gyro) > 1e-3)
    plant.step(dt)
    np.testing.assert_allclose(plant.w, w + dt * np.linalg.solve(inertia, gyro), rtol=1e-12)


def test_a_slipping_brake_pays_out_at_its_slip_speed_and_a_held_one_slips_past_its_torque():
    """rowc, brakes closed: a brake slipping at 1 rad/s (a fault) turns its drum at exactly
    that speed, paying cable out; a held brake whose torque is beyond what it holds slips
    (Karnopp), within it stays put."""
    model = load_robot(CONFIG / "rowc.toml")
    plant = CdprPlant(model)
    theta0, dt = plant.theta.copy(), plant.opt.physics_dt
    plant.brake_slip[2] = 1.0  # rad/s
    plant.step(10 * dt)
    assert plant.theta_dot[2] == -1.0
    assert plant.theta[2] - theta0[2] == pytest.approx(-10 * dt, rel=1e-12)
    load = plant.drum_ratio[5] * plant.tension[5]  # N·m the cable puts on brake 5
    plant.brake_hold[5] = 1.5
    plant.motor_torque[5] = -(1.5 - load) * 0.99
    plant.step(10 * dt)
    assert plant.theta[5] == theta0[5]
    plant.motor_torque[5] = -(1.5 - load) * 1.2
    plant.step(10 * dt)
    assert plant.theta[5] < theta0[5] and plant.theta_dot[5] < 0.0


def test_the_cables_moment_turns_the_platform_about_its_com():
    """cogiro (its COM off P on every axis), the platform held 0.5 mm off its home at rest, the
    brakes closed: one physics step gives, about the COM, I_w ω̇ = Σ t_i (R b_i − R c) × u_i
    = Σ t_i W[3:, i] − (R c) × Σ t_i u_i — the moment from the inverse kinematics' wrench
    matrix (about P) moved to the COM here, not through the kernel."""
    model = load_robot(CONFIG / "cogiro.toml")
    plant = CdprPlant(model)
    plant.com_pos[:] += [4e-4, -3e-4, 2e-4]  # m: off the equilibrium (a moment), every cable taut
    R, dt = plant.R.copy(), plant.opt.physics_dt
    kin = kinematics_at(plant)
    rc = R @ np.array(model.platform.com)
    assert np.all(np.abs(rc) > 0.01) and len(set(np.round(rc, 6))) == 3
    plant.step(dt)
    t = plant.tension
    assert np.all(t > 0.0)
    moment = kin.W[3:] @ t - np.cross(rc, kin.W[:3] @ t)
    inertia = R @ np.array(model.platform.inertia) @ R.T
    assert np.linalg.norm(moment) > 1.0  # N·m: a turn worth checking
    np.testing.assert_allclose(plant.w, dt * np.linalg.solve(inertia, moment), rtol=1e-9)


def test_a_brake_slipping_either_way_sticks_again_once_its_torque_is_within_the_hold():
    """rowc, brake 5 closed holding 1.5 N·m: a motor torque beyond it turns the drum either
    way (Karnopp's slip), its first step from rest at J θ̈ = τ_net − sign(τ_net) τ_hold, the
    brake's friction against the net torque; brought back within the hold, the friction
    stops the drum within a few steps and it stays put — reeling in (θ̇ > 0) as paying out."""
    model = load_robot(CONFIG / "rowc.toml")
    for sign in (1.0, -1.0):
        plant = CdprPlant(model)
        dt = plant.opt.physics_dt
        load = plant.drum_ratio[5] * plant.tension[5]  # N·m the cable puts on the brake
        plant.brake_hold[5] = 1.5
        plant.motor_torque[5] = load + sign * 1.5 * 1.3
        J, b = plant.rotor_inertia[5], plant.viscous[5]
        plant.step(dt)
        breakaway = sign * (1.5 * 1.3 - 1.5) / J * dt
        assert plant.theta_dot[5] == pytest.approx(breakaway, rel=1e-9)
        plant.step(dt)  # slipping: the friction and the viscous drag against the motion
        net = plant.motor_torque[5] - plant.drum_ratio[5] * plant.tension[5] - sign * 1.5
        slipping = breakaway + (net - b * breakaway) / J * dt
        assert b > 0.0 and plant.theta_dot[5] == pytest.approx(slipping, rel=1e-9)
        plant.step(8 * dt)
        assert sign * plant.theta_dot[5] > 0.0
        plant.motor_torque[5] = plant.drum_ratio[5] * plant.tension[5]  # no load on it
        speed = plant.theta_dot[5]
        plant.step(dt)  # the friction against the motion slows the drum, whatever the load
        net = plant.motor_torque[5] - plant.drum_ratio[5] * plant.tension[5] - sign * 1.5
        slowed = speed + (net - b * speed) / J * dt
        assert sign * slowed > 0.0 and plant.theta_dot[5] == pytest.approx(slowed, rel=1e-9)
        plant.step(50 * dt)
        assert plant.theta_dot[5] == 0.0
        theta = plant.theta[5]
        plant.step(10 * dt)
        assert plant.theta[5] == theta


@pytest.mark.parametrize("config", ["cogiro.toml", "seed000_grippers.toml"])
def test_the_compiled_step_is_the_kernel_run_as_python(config):
    """The physics kernel compiled (numba: no bounds checks) and as Python over numpy (its
    ``py_func``: every index checked, an array one short raises) agree over 20 steps of a
    platform moving and turning under an external wrench, one brake slipping — and with the
    seed000 jaws' dynamics."""
    from sim_backend.physics import physics_kernel

    model = load_robot(CONFIG / config)
    plants = [CdprPlant(model), CdprPlant(model)]
    for plant in plants:
        plant.v[:], plant.w[:] = [0.05, -0.03, 0.04], [0.02, -0.01, 0.03]
        plant.ext_force[:], plant.ext_moment[:] = [5.0, -3.0, 2.0], [0.2, 0.1, -0.3]
        plant.brake_slip[2] = 0.5  # rad/s
    compiled, python = plants
    compiled.step(20 * compiled.opt.physics_dt)
    body, winches, state, inputs, servo = python._args
    physics_kernel.py_func(20, python.opt.physics_dt, python._step_kin.arrays, body, winches,
                           state, inputs, servo, python.tension, *python._jaw_args)  # fmt: skip
    for name in ("com_pos", "R", "v", "w", "theta", "theta_dot", "tension"):
        np.testing.assert_allclose(getattr(python, name), getattr(compiled, name), rtol=1e-9,
                                   atol=1e-12, err_msg=name)  # fmt: skip
    assert np.linalg.norm(python.w - [0.02, -0.01, 0.03]) > 1e-6  # the step did turn it


def test_a_jaws_cable_jb_is_damped_on_its_cables_rate():
    """seed000_grippers, the platform moving, the jaws at rest: each jaw's cable jB differs
    from the platform at rest by its damping times its cable's length rate (central
    differences of the inverse kinematics along P's velocity), the jaw's own rate being 0."""
    model = load_robot(CONFIG / "seed000_grippers.toml")
    still, moving = CdprPlant(model), CdprPlant(model)
    v = np.array([0.04, -0.03, 0.05])  # m/s, no turn
    moving.v[:] = v
    kin, h, p, R = KinematicsData(model), 1e-6, moving.position.copy(), moving.R.copy()

    def lengths(s: float) -> np.ndarray:
        inverse_kinematics(model, kin, p + s * h * v, R)
        return kin.length.copy()

    rate = ((lengths(1.0) - lengths(-1.0)) / (2 * h))[moving.g_cable]
    assert np.all(moving.jaw_speed == 0.0) and np.all(np.abs(rate) > 1e-3)
    for plant in (still, moving):
        plant.step(plant.opt.physics_dt)
    assert np.all(still.jb_tension > 0.0)
    np.testing.assert_allclose(moving.jb_tension - still.jb_tension, moving.g_c_jb * rate,
                               rtol=1e-6)  # fmt: skip


def test_a_drive_braking_on_its_following_error_stops_its_drum_in_that_step():
    """rowc, brakes open, the motors holding the cables' torque: drive 0's position loop
    pulls toward a target 1 rad away with a 10 mrad window and a 1 ms time-out; once past
    it the firmware closes the brake within the physics step — the drum stopped there (θ̇ =
    0), and held from then on."""
    plant = CdprPlant(load_robot(CONFIG / "rowc.toml"))
    plant.brake[:] = False
    plant.motor_torque[:] = plant.drum_ratio * plant.tension
    s = plant.servo
    s.kp[0], s.target[0], s.window[0], s.timeout[0] = 2.0, plant.theta[0] + 1.0, 0.01, 0.001
    dt = plant.opt.physics_dt
    for _ in range(100):
        plant.step(dt)
        if plant.brake[0]:
            break
    assert plant.brake[0] and not np.any(plant.brake[1:])
    assert plant.theta_dot[0] == 0.0
    theta = plant.theta[0]
    plant.step(10 * dt)
    assert plant.theta[0] == theta


def test_a_cable_pulling_half_a_newton_pulls_the_platform():
    """cogiro, every cable cut but one, slipped on its drum until it pulls ~0.5 N: one physics
    step gives v = dt (t u / m + g), its small force counted like any other."""
    model = load_robot(CONFIG / "cogiro.toml")
    plant = CdprPlant(model)
    stretch = plant.drum_ratio[0] * plant.theta[0] - plant.drum_slip[0]  # m, at home
    plant.cable_cut[1:] = True
    plant.drum_slip[0] += stretch * (1.0 - 0.5 / plant.tension[0])  # the law near-linear
    kin = kinematics_at(plant)
    u, dt = kin.W[:3, 0].copy(), plant.opt.physics_dt
    plant.step(dt)
    t = plant.tension[0]
    assert 0.3 < t < 0.7
    g = np.array(model.gravity)
    np.testing.assert_allclose(plant.v, dt * (t * u / model.platform.mass + g), rtol=1e-9)


def test_a_closed_brake_holds_a_drum_with_no_load_at_all():
    """rowc, cable 3 cut (no tension), no motor torque, its brake closed: nothing acts on the
    drum, and it stays exactly where it is."""
    plant = CdprPlant(load_robot(CONFIG / "rowc.toml"))
    plant.cable_cut[3] = True
    plant.motor_torque[:] = 0.0
    theta = plant.theta[3]
    plant.step(20 * plant.opt.physics_dt)
    assert plant.tension[3] == 0.0 and plant.brake[3]
    assert plant.theta_dot[3] == 0.0 and plant.theta[3] == theta


def test_a_cable_at_exactly_its_unstretched_length_carries_nothing_even_lengthening():
    """rowc, cable 2's drum set so the cable is exactly its unstretched length (a stretch of
    0.0), the platform moving to lengthen it: no tension — its damping acts only on a
    stretched cable."""
    model = load_robot(CONFIG / "rowc.toml")
    plant = CdprPlant(model)
    kin = kinematics_at(plant)
    plant.theta[2], plant.drum_slip[2] = 0.0, kin.length[2] - plant.l_home[2]
    assert kin.length[2] - plant.unstretched_length()[2] == 0.0
    plant.v[:] = -0.1 * kin.W[:3, 2]  # m/s, away from its exit point
    plant.step(plant.opt.physics_dt)
    assert plant.tension[2] == 0.0


def test_a_jaws_cable_jb_never_pushes():
    """seed000_grippers: a jaw held 0.5 N's worth of jB stretch beyond its cable's (jB
    compressed), at rest: jB carries nothing, not −0.5 N; held that much short of it, jB
    carries its 0.5 N."""
    model = load_robot(CONFIG / "seed000_grippers.toml")
    plant = CdprPlant(model)
    j, i = 0, int(plant.g_cable[0])
    kin = kinematics_at(plant)
    e = kin.length[i] - plant.unstretched_length()[i]  # m, the cable's stretch
    assert e > 0.0
    plant.jaw_travel[j] = e + 0.5 / plant.g_k_jb[j]
    plant.step(plant.opt.physics_dt)
    assert plant.jb_tension[j] == 0.0
    plant = CdprPlant(model)
    plant.jaw_travel[j] = e - 0.5 / plant.g_k_jb[j]
    plant.step(plant.opt.physics_dt)
    assert plant.jb_tension[j] == pytest.approx(0.5, rel=1e-6)
