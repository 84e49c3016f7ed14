"""Cable tensions to winch motor torques, ``τ = (r/G) t c_p + f(θ̇) + J θ̈_d`` within each motor's
limit (θ > 0 winds in), ``f`` the winch's friction and ``c_p`` its pulley's capstan factor
(``numerics.friction_law``, ``numerics.capstan_factor``: the law written once, for the torques,
the tension estimate that takes it back out of the drives' torques, the simulated plant and
``cdprctl calibrate friction``). Compiled: one call instead of ~12 numpy operations (~20 µs a
cycle on this VM). Each winch's terms are the robot file's until a friction calibration's
record replaces them (``apply_friction``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numba import njit

from cdprctl.core.numerics import (
    FRICTION_SMOOTHING,
    capstan_factor,
    clamp,
    cycle_kernel,
    friction_law,
    kernel_args,
)
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel

__all__ = ["FRICTION_SMOOTHING"]


@njit(cache=True)
def friction_torque(viscous, coulomb, stribeck, w):  # pragma: no cover - compiled
    """N·m a winch's friction takes at motor speed ``w`` (rad/s), at the controller's
    smoothing (``numerics.friction_law``)."""
    return friction_law(viscous, coulomb, stribeck, w, FRICTION_SMOOTHING)


@njit(cache=True)
def applied_tension(
    torque, viscous, coulomb, stribeck, capstan, w, accel_term, r
):  # pragma: no cover - compiled
    """N a winch applies to its cable on the platform's side of its pulley from the drive's
    measured motor ``torque`` (N·m): the torque law taken back, less friction at motor speed
    ``w`` (rad/s) and the rotor-inertia term ``accel_term`` (N·m), over ``r`` (m/rad) and the
    pulley's capstan factor (``capstan`` = μ β; winding in, the winch side pulls more)."""
    winch_side = (torque - friction_torque(viscous, coulomb, stribeck, w) - accel_term) / r
    return winch_side / capstan_factor(capstan, w, FRICTION_SMOOTHING)


@njit(cache=True)
def friction_kernel(winches, velocity, cables, out):  # pragma: no cover - compiled
    """``out[j]`` ← the friction torque (N·m) of winch ``cables[j]`` at ``velocity`` (rad/s)
    (``winches``: the :class:`WinchTerms`)."""
    _, viscous, coulomb, stribeck = winches[0], winches[1], winches[2], winches[3]
    for j in range(cables.shape[0]):
        i = cables[j]
        out[j] = friction_torque(viscous[i], coulomb[i], stribeck[i], velocity[i])


@cycle_kernel
def winch_torque_kernel(
    tensions, winches, WT, acceleration, velocity, friction, out
):  # pragma: no cover - compiled
    """``out`` ← ``τ = r t c_p + f(θ̇) + J θ̈_d`` (N·m) within ±``limit`` (``winches``: the
    :class:`WinchTerms`).

    ``r`` (m/rad) the drum radius over the gear ratio, ``t`` (N) the tensions, ``θ̇``
    (rad/s) the motor velocities, the friction ``f`` and the pulley's capstan factor ``c_p``
    only when ``friction``; the rotor's
    ``θ̈_d = Wᵀ a_d / r`` from the desired platform acceleration ``a_d`` (``δl = −Wᵀ δX`` and
    ``l0 = l − r θ``: θ > 0 winds in).
    """
    r, viscous, coulomb, stribeck, capstan, rotor_inertia, limit = winches
    for i in range(out.shape[0]):
        tau = r[i] * tensions[i]
        if friction:
            tau *= capstan_factor(capstan[i], velocity[i], FRICTION_SMOOTHING)
            tau += friction_torque(viscous[i], coulomb[i], stribeck[i], velocity[i])
        acc = 0.0
        for a in range(6):
            acc += WT[i, a] * acceleration[a]
        tau += rotor_inertia[i] * acc / r[i]
        out[i] = clamp(tau, -limit[i], limit[i])


class WinchTerms(NamedTuple):
    """Each winch's terms of the torque law, per cable (the kernels take them as
    ``kernel_args``): ``r`` (m/rad) the drum radius over the gear ratio, ``viscous``
    (N·m·s/rad), ``coulomb`` and ``stribeck`` (N·m), ``capstan`` the pulley's μ β (μ times the
    wrap at the home pose, rad: a few degrees of wrap change over the workspace are neglected),
    ``rotor_inertia`` (kg·m²), ``limit`` (N·m)."""

    r: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    stribeck: np.ndarray
    capstan: np.ndarray
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
        self.stribeck = np.array([x.stribeck_friction for x in w])  # N·m
        self.wrap = home_wrap(model)  # rad
        self.pulley = np.array([x.pulley_friction for x in w])  # μ
        self.capstan = self.pulley * self.wrap
        self.limit = np.array([x.torque_limit for x in w])  # N·m
        self.friction_compensation = model.control.friction_compensation
        self._J_over_r = self.rotor_inertia / self.r
        self.terms = kernel_args(WinchTerms(
            self.r, self.viscous, self.coulomb, self.stribeck, self.capstan,
            self.rotor_inertia, self.limit,
        ))  # fmt: skip

    def apply_friction(self, viscous: Sequence[float], coulomb: Sequence[float],
                       stribeck: Sequence[float], pulley: Sequence[float]) -> None:  # fmt: skip
        """Each winch's identified friction (N·m·s/rad, N·m, N·m) and pulley μ in place of the
        file's (a friction calibration's record), written into the kernels' arrays."""
        self.viscous[:] = viscous
        self.coulomb[:] = coulomb
        self.stribeck[:] = stribeck
        self.pulley[:] = pulley
        np.multiply(self.pulley, self.wrap, out=self.capstan)

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


def home_wrap(model: RobotModel) -> FloatArray:
    """rad each cable wraps its swivel pulley at the home pose (0 without one)."""
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    return np.array(kin.wrap_angle, dtype=float)
