"""Cable tensions to winch motor torques, ``τ = (r/G) t + b θ̇ + τ_c tanh(θ̇/ω_ε) + J θ̈_d``
within each motor's limit (θ > 0 winds in). Compiled: one call instead of ~12 numpy operations
(~20 µs a cycle on this VM). The friction law is written once, here, for the torques and for
the grasp sensing that takes it back out of the drives' torques."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from cdprctl.model.robot import RobotModel
from cdprctl.numerics import clamp, cycle_kernel, kernel_args
from cdprctl.rotation import FloatArray

#: rad/s: the Coulomb friction model's ``tanh(θ̇/ω_ε)`` smoothing of the sign
FRICTION_SMOOTHING = 0.05


@njit(cache=True)
def friction_torque(viscous, coulomb, w):  # pragma: no cover - compiled
    """N·m a winch's friction takes at motor speed ``w`` (rad/s)."""
    return viscous * w + coulomb * math.tanh(w / FRICTION_SMOOTHING)


@njit(cache=True)
def applied_tension(torque, viscous, coulomb, w, accel_term, r):  # pragma: no cover - compiled
    """N a winch applies to its cable from the drive's measured motor ``torque`` (N·m): the
    torque law taken back, less friction at motor speed ``w`` (rad/s) and the rotor-inertia
    term ``accel_term`` (N·m), over ``r`` (m/rad)."""
    return (torque - friction_torque(viscous, coulomb, w) - accel_term) / r


@njit(cache=True)
def friction_kernel(viscous, coulomb, velocity, cables, out):  # pragma: no cover - compiled
    """``out[j]`` ← the friction torque (N·m) of winch ``cables[j]`` at ``velocity`` (rad/s)."""
    for j in range(cables.shape[0]):
        i = cables[j]
        out[j] = friction_torque(viscous[i], coulomb[i], velocity[i])


@cycle_kernel
def winch_torque_kernel(
    tensions, winches, WT, acceleration, velocity, friction, out
):  # pragma: no cover - compiled
    """``out`` ← ``τ = r t + b θ̇ + τ_c tanh(θ̇/ω_ε) + J θ̈_d`` (N·m) within ±``limit``
    (``winches``: the :class:`WinchTerms`).

    ``r`` (m/rad) the drum radius over the gear ratio, ``t`` (N) the tensions, ``θ̇``
    (rad/s) the motor velocities, friction terms only when ``friction``; the rotor's
    ``θ̈_d = Wᵀ a_d / r`` from the desired platform acceleration ``a_d`` (``δl = −Wᵀ δX`` and
    ``l0 = l − r θ``: θ > 0 winds in).
    """
    r, viscous, coulomb, rotor_inertia, limit = winches
    for i in range(out.shape[0]):
        tau = r[i] * tensions[i]
        if friction:
            tau += friction_torque(viscous[i], coulomb[i], velocity[i])
        acc = 0.0
        for a in range(6):
            acc += WT[i, a] * acceleration[a]
        tau += rotor_inertia[i] * acc / r[i]
        out[i] = clamp(tau, -limit[i], limit[i])


class WinchTerms(NamedTuple):
    """Each winch's terms of the torque law, per cable (the kernels take them as
    ``kernel_args``): ``r`` (m/rad) the drum radius over the gear ratio, ``viscous``
    (N·m·s/rad), ``coulomb`` (N·m), ``rotor_inertia`` (kg·m²), ``limit`` (N·m)."""

    r: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    rotor_inertia: np.ndarray
    limit: np.ndarray


class WinchTorques:
    """The winches' parameters, per cable, as the kernels take them (``terms``)."""

    def __init__(self, model: RobotModel):
        w = [x.winch for x in model.cables]
        self.r = np.array([x.drum_radius / x.gear_ratio for x in w])  # m/rad
        self.rotor_inertia = np.array([x.rotor_inertia for x in w])  # kg·m²
        self.viscous = np.array([x.viscous_friction for x in w])  # N·m·s/rad
        self.coulomb = np.array([x.coulomb_friction for x in w])  # N·m
        self.limit = np.array([x.torque_limit for x in w])  # N·m
        self.friction_compensation = model.control.friction_compensation
        self._J_over_r = self.rotor_inertia / self.r
        self.terms = kernel_args(
            WinchTerms(self.r, self.viscous, self.coulomb, self.rotor_inertia, self.limit)
        )

    def rotor_term(self, WT: FloatArray, acceleration: FloatArray, out: FloatArray) -> None:
        """``out`` (N·m) ← the rotor-inertia feed-forward ``J θ̈_d = J Wᵀ a_d / r`` of the
        torque law, for taking it back out of measured torques (observer, cable space)."""
        np.dot(WT, acceleration, out=out)
        out *= self._J_over_r

    def update(
        self,
        tensions: FloatArray,
        WT: FloatArray,
        acceleration: FloatArray,
        motor_velocity: FloatArray,
        active: bool,
        out: FloatArray,
    ) -> None:
        """``out`` (N·m) ← the torques for ``tensions`` (N); zero when not ``active``."""
        if not active:
            out[:] = 0.0
            return
        winch_torque_kernel(
            tensions, self.terms, WT, acceleration, motor_velocity, self.friction_compensation,
            out,
        )  # fmt: skip
