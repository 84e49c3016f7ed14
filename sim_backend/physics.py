"""The simulated robot's physics steps, compiled (numba): cable forces, winches, the platform
and, through ``jaw_dynamics.py``, the jaws (the conventions are ``plant.py``'s). The kernel
takes named bundles of the plant's own arrays, written in place."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from cdprctl.core.numerics import (
    Compliance,
    capstan_factor,
    compliance_at,
    cycle_kernel,
    friction_law,
)
from cdprctl.core.rotation import exp_so3_kernel
from cdprctl.geometry.kinematics import ik_kernel
from sim_backend.jaw_dynamics import jaw_dynamics
from sim_backend.servo import following_error, servo_torque


class Body(NamedTuple):
    """The platform: COM (m, platform frame), mass (kg), inertia (kg·m², platform frame,
    about the COM), gravity (m/s², base frame)."""

    com: np.ndarray
    mass: float
    inertia: np.ndarray
    gravity: np.ndarray


class Winches(NamedTuple):
    """Per cable: home length (m), drum radius over gear ratio (m/rad), rotor inertia
    (kg·m²), viscous (N·m·s/rad), Coulomb and Stribeck (N·m) friction, the Coulomb smoothing
    (rad/s), the cable law, the cable damping (N·s/m), its pulley's capstan μ."""

    l_home: np.ndarray
    drum_ratio: np.ndarray
    rotor_inertia: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    stribeck: np.ndarray
    coulomb_velocity: float
    law: Compliance
    damping: np.ndarray
    pulley_friction: np.ndarray


class BodyState(NamedTuple):
    """COM position (m) and orientation, COM velocity (m/s) and ω (rad/s, base frame), motor
    angles (rad) and speeds (rad/s)."""

    com_pos: np.ndarray
    R: np.ndarray
    v: np.ndarray
    w: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray


class Inputs(NamedTuple):
    """Motor torques (N·m), brakes, a brake's slip speed (rad/s), the torque a closed brake
    holds before it slips (N·m at the motor), cut cables, cable slipped off the drums (m), the
    external force (N at P) and moment (N·m), base frame."""

    motor_torque: np.ndarray
    brake: np.ndarray
    brake_slip: np.ndarray
    brake_hold: np.ndarray
    cable_cut: np.ndarray
    drum_slip: np.ndarray
    ext_force: np.ndarray
    ext_moment: np.ndarray


@njit(cache=True)
def physics_kernel(
    n, dt, kin, body, winches, state, inputs, servo, tension, jaws, jaw_state
):  # pragma: no cover - compiled
    """``n`` explicit steps of ``dt`` (s): cable forces from the stretch of each cable
    (``winches.law``) and its damping, winch dynamics with brakes and capstan friction, the
    platform by Newton-Euler (with jaws: ``jaw_dynamics``). ``kin``: the steps' IK arrays;
    ``tension`` (N) out; the bundles are the plant's (``Body``, ``Winches``, ``BodyState``,
    ``Inputs``, ``Servo``, ``Jaws``, ``JawState``, as plain tuples: ``numerics.kernel_args``)."""
    com, mass, inertia, g = body
    l_home, drum_ratio, J, visc, coul, strib, coul_v, law, damping, mu_p = winches
    com_pos, R, v, w, theta, theta_dot = state
    tau_m, brake, slip, hold, cut, drum_slip, f_ext, m_ext = inputs
    g_of_cable, _, g_mass, _, _, _, _, _, g_kjb, g_cjb, _, _, _, _, _ = jaws
    q, qd, g_tb, _ = jaw_state
    rbT, wrap, length, W = kin[4], kin[8], kin[9], kin[10]  # KinArrays
    m = l_home.shape[0]
    ng = g_mass.shape[0]
    P = np.empty(3)
    twist = np.empty(6)
    for _ in range(n):
        Rc = R @ com
        for a in range(3):
            P[a] = com_pos[a] - Rc[a]
        ik_kernel(kin, P, R)
        # twist at P: v_P = v_com + ω × (P − COM) = v_com − ω × Rc
        twist[0] = v[0] - (w[1] * Rc[2] - w[2] * Rc[1])
        twist[1] = v[1] - (w[2] * Rc[0] - w[0] * Rc[2])
        twist[2] = v[2] - (w[0] * Rc[1] - w[1] * Rc[0])
        twist[3], twist[4], twist[5] = w[0], w[1], w[2]
        F = np.zeros(3)
        M = np.zeros(3)  # about the COM
        for i in range(m):
            l0 = l_home[i] - drum_ratio[i] * theta[i] + drum_slip[i]
            e = length[i] - l0
            t = 0.0
            if e > 0.0 and not cut[i]:
                t = cable_tension(i, l0, e, twist, W, drum_ratio, law, damping, theta_dot,
                                  g_of_cable, g_kjb, g_cjb, q, qd, g_tb)  # fmt: skip
            elif g_of_cable[i] >= 0:
                g_tb[g_of_cable[i]] = 0.0
            tension[i] = t
            if t > 0.0:
                add_cable_wrench(i, t, W, rbT, Rc, F, M)
            winch_step(i, t, dt, drum_ratio, J, visc, coul, strib, coul_v, mu_p, wrap, theta,
                       theta_dot, tau_m, brake, slip, hold, servo)  # fmt: skip
        # external wrench at P: moment about the COM adds (P − COM) × f = −Rc × f
        for a in range(3):
            F[a] += mass * g[a] + f_ext[a]
            M[a] += m_ext[a]
        M[0] += -(Rc[1] * f_ext[2] - Rc[2] * f_ext[1])
        M[1] += -(Rc[2] * f_ext[0] - Rc[0] * f_ext[2])
        M[2] += -(Rc[0] * f_ext[1] - Rc[1] * f_ext[0])
        # Newton-Euler at the COM, world frame: I_w ω̇ = M − ω × I_w ω
        Iw = R @ inertia @ R.T
        Iww = Iw @ w
        rhs = np.empty(3)
        rhs[0] = M[0] - (w[1] * Iww[2] - w[2] * Iww[1])
        rhs[1] = M[1] - (w[2] * Iww[0] - w[0] * Iww[2])
        rhs[2] = M[2] - (w[0] * Iww[1] - w[1] * Iww[0])
        if ng == 0:
            wdot = np.linalg.solve(Iw, rhs)
            for a in range(3):
                v[a] += F[a] / mass * dt
                w[a] += wdot[a] * dt
        else:
            jaw_dynamics(dt, P, R, com_pos, v, w, F, rhs, mass, Iw, g, rbT, jaws, jaw_state)
        for a in range(3):
            com_pos[a] += v[a] * dt
        # R ← exp([ω dt]×) R
        E = np.empty((3, 3))
        exp_so3_kernel(w[0] * dt, w[1] * dt, w[2] * dt, E)
        R[:, :] = E @ R


# The per-cable steps take the arrays, not the bundles, and without reference counting
# (``cycle_kernel``): with
# it, each call counted every array it was handed in and out, and the kernel took 1.5 times as
# long (measured on rowc, 10 physics steps: 90 µs against 58 µs of CPU).
@cycle_kernel
def cable_tension(i, l0, e, twist, W, drum_ratio, law, damping, theta_dot, g_of_cable, g_kjb,
                  g_cjb, q, qd, g_tb):  # pragma: no cover - compiled
    """Cable ``i``'s tension (N) at stretch ``e`` (m) of its unstretched length ``l0`` (m):
    its law's stiffness and its damping of the stretch rate, never pushing; where the cable
    splits to a jaw (jA the spring, jB to the jaw), jB's tension added and kept in ``g_tb``
    (N, per jaw). ``twist``: the platform's at P (base frame), ``W`` the wrench matrix."""
    k = 1.0 / compliance_at(law, i, l0)
    ldot = 0.0
    for a in range(6):
        ldot -= W[a, i] * twist[a]  # dl/dt = −Wᵀ twist
    edot = ldot + drum_ratio[i] * theta_dot[i]
    t = k * e + damping[i] * edot
    if t < 0.0:
        t = 0.0
    j = g_of_cable[i]
    if j >= 0:  # the cable splits: jA (the spring, t) and jB to the jaw
        tb = g_kjb[j] * (e - q[j]) + g_cjb[j] * (edot - qd[j])
        g_tb[j] = tb if tb > 0.0 else 0.0
        t += g_tb[j]
    return t


@cycle_kernel
def add_cable_wrench(i, t, W, rbT, Rc, F, M):  # pragma: no cover - compiled
    """``F`` (N) and ``M`` (N·m, about the COM) += cable ``i``'s pull of ``t`` (N) along its
    unit vector (``W``'s column), at its attachment ``rbT`` (m, base frame, from P); ``Rc``:
    the COM from P (m, base frame)."""
    fx, fy, fz = t * W[0, i], t * W[1, i], t * W[2, i]
    F[0] += fx
    F[1] += fy
    F[2] += fz
    # moment about the COM: (R b_i − R c) × f
    rx, ry, rz = rbT[0, i] - Rc[0], rbT[1, i] - Rc[1], rbT[2, i] - Rc[2]
    M[0] += ry * fz - rz * fy
    M[1] += rz * fx - rx * fz
    M[2] += rx * fy - ry * fx


@cycle_kernel
def winch_step(i, t, dt, drum_ratio, J, visc, coul, strib, coul_v, mu_p, wrap, theta, theta_dot,
               tau_m, brake, slip, hold, servo):  # pragma: no cover - compiled
    """Winch ``i`` over ``dt`` (s) under the cable's tension ``t`` (N): J θ̈ = τ_m − (r/G) t_w
    − f(θ̇) (``numerics.friction_law``, the pulley's capstan friction), or its brake: slipping
    (a fault), holding, or slipping under a torque beyond what it holds."""
    if brake[i] and slip[i] != 0.0:
        theta_dot[i] = -slip[i]  # a slipping brake (a fault) pays cable out
        theta[i] += theta_dot[i] * dt
    elif brake[i]:
        # a closed brake: at rest while the torque on it (the drive's, with the brake
        # closed while enabled, a brake test's, and the cable's) is within what it
        # holds; beyond, it slips with that torque as its friction, and sticks again
        # when the drum stops (Karnopp's stick-slip friction)
        tau = servo_torque(servo, i, theta[i], theta_dot[i], tau_m[i], dt)
        load = tau - drum_ratio[i] * t
        if theta_dot[i] == 0.0 and abs(load) <= hold[i]:
            return
        moving = theta_dot[i] if theta_dot[i] != 0.0 else load
        friction = hold[i] if moving > 0.0 else -hold[i]
        rate = theta_dot[i] + (load - friction - visc[i] * theta_dot[i]) / J[i] * dt
        if rate * moving < 0.0:
            rate = 0.0  # it stopped within the step: held again
        theta_dot[i] = rate
        theta[i] += rate * dt
    else:
        tau = servo_torque(servo, i, theta[i], theta_dot[i], tau_m[i], dt)
        closes = following_error(servo, i)  # the drive's firmware brakes
        cap = 1.0
        if mu_p[i] > 0.0 and wrap[i] > 0.0:
            cap = capstan_factor(mu_p[i] * wrap[i], theta_dot[i], coul_v)
        friction = friction_law(visc[i], coul[i], strib[i], theta_dot[i], coul_v)
        acc = (tau - drum_ratio[i] * t * cap - friction) / J[i]
        theta_dot[i] += acc * dt
        theta[i] += theta_dot[i] * dt
        if closes:  # it holds the drum from the next step on (as ``close_brake``)
            brake[i] = True
            theta_dot[i] = 0.0
