"""The torque law of ``control/cycle/torques.py`` against its formula written out independently in
numpy, on seeded inputs that reach past each motor's limit: the controller's own clamp, not
only the driver's, keeps every torque within ``torque_limit`` (``ControlData.torques`` is what
telemetry, the observer and the cable-space estimate read)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.control.cycle.torques import WinchTorques, applied_tension, friction_kernel
from cdprctl.robot_file import load_robot

SMOOTHING = 0.05  # rad/s: the Coulomb model's tanh(θ̇/ω_ε), as numerics.py documents it
STRIBECK = 2.0  # rad/s: the Stribeck term's exp(−(θ̇/ω_s)²)


def with_pulleys_and_stribeck(model):
    """``model`` whose winches each have their own Stribeck term and pulley μ (seeded)."""
    rng = np.random.default_rng(46)
    cables = tuple(
        dataclasses.replace(c, winch=dataclasses.replace(
            c.winch, stribeck_friction=float(rng.uniform(0.01, 0.05)),
            pulley_friction=float(rng.uniform(0.02, 0.1))))
        for c in model.cables
    )  # fmt: skip
    return dataclasses.replace(model, cables=cables)


def wrap_angles(model):
    """rad each cable wraps its pulley at home, from the pulley's geometry written out: the
    cable leaves the wheel tangentially towards the attachment (β = π − φ)."""
    from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics

    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    return kin.wrap_angle.copy()


def reference_torques(model, tensions, WT, acceleration, velocity, friction):
    """``τ = (r/G) t e^{μβ tanh(θ̇/ω_ε)} + b θ̇ + (τ_c + τ_s e^{−(θ̇/ω_s)²}) tanh(θ̇/ω_ε)
    + J Wᵀ a / (r/G)`` within ±limit, per cable."""
    w = [c.winch for c in model.cables]
    r = np.array([x.drum_radius / x.gear_ratio for x in w])
    tau = r * tensions
    sign = np.tanh(velocity / SMOOTHING)
    if friction:
        mu = np.array([x.pulley_friction for x in w])
        tau = tau * np.exp(mu * wrap_angles(model) * sign)
        tau += np.array([x.viscous_friction for x in w]) * velocity
        tau += np.array([x.coulomb_friction for x in w]) * sign
        stribeck = np.array([x.stribeck_friction for x in w])
        tau += stribeck * np.exp(-((velocity / STRIBECK) ** 2)) * sign
    tau += np.array([x.rotor_inertia for x in w]) * (WT @ acceleration) / r
    limit = np.array([x.torque_limit for x in w])
    return np.minimum(limit, np.maximum(-limit, tau)), tau, limit


@pytest.mark.parametrize("robot_file", ["rowc.toml", "seed000.toml", "caroca_pulleys.toml"])
@pytest.mark.parametrize("friction", [False, True])
def test_torques_follow_the_law_and_never_leave_their_limit(robot_file, friction):
    model = with_pulleys_and_stribeck(load_robot(CONFIG / robot_file))
    model = dataclasses.replace(
        model, control=dataclasses.replace(model.control, friction_compensation=friction)
    )
    wt = WinchTorques(model)
    m = model.n_cables
    rng = np.random.default_rng(44)
    out = np.empty(m)
    beyond = 0
    t_max = float(np.max([c.tension_max for c in model.cables]))
    for _ in range(200):
        # tensions from slack to five times the largest allowed, both signs of every term
        tensions = rng.uniform(-0.5, 5.0, m) * t_max
        WT = rng.normal(size=(m, 6))
        acceleration = rng.normal(scale=5.0, size=6)
        velocity = rng.normal(scale=50.0, size=m)
        wt.update(tensions, WT, acceleration, velocity, True, out)
        expected, raw, limit = reference_torques(model, tensions, WT, acceleration, velocity,
                                                 friction)  # fmt: skip
        np.testing.assert_allclose(out, expected, rtol=1e-12, atol=1e-12)
        assert np.all(np.abs(out) <= limit)
        beyond += int(np.sum(np.abs(raw) > limit))
    assert beyond > 100  # the clamp was exercised, on both sides
    wt.update(np.full(m, 10 * t_max), np.zeros((m, 6)), np.zeros(6), np.zeros(m), True, out)
    np.testing.assert_array_equal(out, [c.winch.torque_limit for c in model.cables])
    wt.update(np.full(m, -10 * t_max), np.zeros((m, 6)), np.zeros(6), np.zeros(m), True, out)
    np.testing.assert_array_equal(out, [-c.winch.torque_limit for c in model.cables])


def test_inactive_torques_are_zero():
    model = load_robot(CONFIG / "rowc.toml")
    wt = WinchTorques(model)
    out = np.full(model.n_cables, 7.0)
    wt.update(np.full(model.n_cables, 100.0), np.ones((model.n_cables, 6)), np.ones(6),
              np.ones(model.n_cables), False, out)  # fmt: skip
    assert np.all(out == 0.0)


def test_the_rotor_term_is_the_laws_inertia_part():
    model = load_robot(CONFIG / "rowc.toml")
    wt = WinchTorques(model)
    rng = np.random.default_rng(7)
    WT, a = rng.normal(size=(model.n_cables, 6)), rng.normal(size=6)
    out = np.empty(model.n_cables)
    wt.rotor_term(WT, a, out)
    _, raw, _ = reference_torques(model, np.zeros(model.n_cables), WT, a,
                                  np.zeros(model.n_cables), False)  # fmt: skip
    np.testing.assert_allclose(out, raw, rtol=1e-12)


def test_applied_tension_takes_the_law_back():
    """The grasp sensing's and the cable space's ``applied_tension`` inverts the torque law:
    from the torque the law gives for a tension (friction and the rotor's term included),
    it returns that tension, per cable, at speeds of both signs, pulleys' losses included."""
    model = with_pulleys_and_stribeck(load_robot(CONFIG / "caroca_pulleys.toml"))
    wrap = wrap_angles(model)
    assert np.all(wrap > 0.1)
    rng = np.random.default_rng(45)
    m = model.n_cables
    for _ in range(50):
        t = rng.uniform(0.0, 200.0, m)
        WT, a, w = rng.normal(size=(m, 6)), rng.normal(size=6), rng.normal(scale=3.0, size=m)
        _, tau, _ = reference_torques(model, t, WT, a, w, True)
        rotor = reference_torques(model, np.zeros(m), WT, a, np.zeros(m), False)[1]
        for i, c in enumerate(model.cables):
            x = c.winch
            r = x.drum_radius / x.gear_ratio
            got = applied_tension(tau[i], x.viscous_friction, x.coulomb_friction,
                                  x.stribeck_friction, x.pulley_friction * wrap[i], w[i],
                                  rotor[i], r)  # fmt: skip
            assert got == pytest.approx(t[i], rel=1e-12, abs=1e-9)


def test_friction_kernel_takes_the_cables_it_is_given():
    model = with_pulleys_and_stribeck(load_robot(CONFIG / "seed000.toml"))
    wt = WinchTorques(model)
    velocity = np.linspace(-2.0, 2.0, model.n_cables)
    cables = np.array([7, 0, 3], dtype=np.int64)
    out = np.empty(3)
    friction_kernel(wt.terms, velocity, cables, out)
    full = reference_torques(model, np.zeros(model.n_cables), np.zeros((model.n_cables, 6)),
                             np.zeros(6), velocity, True)[1]  # fmt: skip
    np.testing.assert_allclose(out, full[cables], rtol=1e-12)
