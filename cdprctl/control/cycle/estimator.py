"""Platform state from the winch encoders.

Motor angles → unstretched cable lengths (``l0 = l_zero − (r/G) θ``, ``l_zero`` each cable's
unstretched length where its encoder reads zero: the length at the home pose unless a
calibration record says otherwise, ``apply_calibration`` and docs/homing.md) → stretched
lengths under the tensions the caller gives (the controller passes feed-forward tensions,
docs/control.md) → forward kinematics warm-started from
the last pose → twist by finite differences of successive poses through a first-order low-pass
filter (cut-off ``[control] velocity_filter`` Hz): ``v ← v + α (Δp/Δt − v)``,
``α = 1 − exp(−2π f_c Δt)``; the angular velocity from ``log(R_k R_(k−1)ᵀ)/Δt``. The poses
include the elastic stretch, so the platform's motion on its cables is seen too (a twist from the
motor rates, ``l̇ = −Wᵀ ẋ``, misses it and lost the damping of a lateral push in the lock-step
tests).

Feedback of different ages (a drive's frame a cycle late or lost on a lossy bus) is brought to
one instant, the newest sample's, by ``θ + θ̇ (age − age_min)`` before the forward kinematics,
and ``Δt`` is taken between sample instants, not read times: otherwise one late drive shifts the
pose by a cycle of that cable's motion and ``Δp/Δt`` spikes (tests/control/cycle/test_estimator.py:
0.05 m/s and more at 0.3 m/s with one drive late every third cycle).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from cdprctl.core.numerics import (
    compliance_at,
    compliance_of,
    cycle_kernel,
    kernel_args,
    stiffness_kernel,
)
from cdprctl.core.rotation import FloatArray, log_so3_kernel
from cdprctl.geometry.forward_kinematics import (
    FKResult,
    FKStatus,
    ForwardKinematics,
    copy_pose,
    fk_kernel,
    rotation_since,
)
from cdprctl.geometry.kinematics import KinematicsData, ik_kernel, inverse_kinematics
from cdprctl.model.robot import RobotModel


class Estimator:
    def __init__(self, model: RobotModel):
        self.model = model
        c = model.cables
        self.drum_ratio = np.array([x.winch.drum_radius / x.winch.gear_ratio for x in c])
        kin = KinematicsData(model)
        inverse_kinematics(model, kin, model.home.position, model.home.rotation)
        self.l_home = kin.length.copy()  # m, geometric lengths at the home pose
        self.nominal_drum_ratio = self.drum_ratio.copy()  # m/rad, the config's r/G
        # m: each cable's unstretched length where its encoder reads zero (written in place:
        # the cable-space targets and the grippers read the same array)
        self.l_zero = self.l_home.copy()
        self.law = compliance_of(c)  # the cable law's terms (cdprctl.core.numerics)
        self._law = kernel_args(self.law)
        # the winding as the cable-space kernels take it: (the law's terms, l_zero m, r/G
        # m/rad), arrays written in place (calibrate): handed to the cable space in each call
        self.winding = (self._law, self.l_zero, self.drum_ratio)
        # A gripper cable's length is the jaw's travel plus the pose (Sensors 2019 §2.4): the
        # pose comes from the other cables, the grippers take the redundancy (docs/gripper.md).
        grip = {g.cable for g in model.grippers}
        self.fk_cables = np.array([i for i in range(model.n_cables) if i not in grip])
        fk_model = (
            dataclasses.replace(model, cables=tuple(c[i] for i in self.fk_cables), grippers=())
            if grip
            else model
        )
        self.fk = ForwardKinematics(fk_model, max_iterations=8)  # warm: 1-2 are the norm
        self.kin = KinematicsData(model)  # at the estimated pose: W, lengths for the TDA
        self.position = np.array(model.home.position, dtype=float)
        self.rotation = np.array(model.home.rotation, dtype=float)
        self.velocity = np.zeros(3)  # m/s, base frame
        self.omega = np.zeros(3)  # rad/s, base frame
        self.last_fk: FKResult | None = None
        self.lengths = np.zeros(model.n_cables)
        # [s of the last sample, 2π f_c (rad/s) of the velocity filter]
        self._clock = np.array([-math.inf, 2.0 * math.pi * model.control.velocity_filter])
        self._theta = np.zeros(model.n_cables)  # rad, the angles brought to one instant
        self._fk_p = np.zeros(3)
        self._fk_R = np.eye(3)
        self._info = np.zeros(3)  # FK: RMS residual (m), iterations, FKStatus
        self.k = np.zeros(model.n_cables)  # N/m, each cable's at the estimated pose
        stiffness_kernel(self.l_home, self._law, self.k)
        nf = len(self.fk_cables)
        scratch = FKScratch(self._theta, self.lengths, np.zeros(nf), np.zeros(nf), self._fk_p,
                            self._fk_R, self._info, np.zeros((3, 3)), np.zeros(3))  # fmt: skip
        self._scratch = kernel_args(scratch)
        state = EstimateState(self.position, self.rotation, self.velocity, self.omega,
                              self._clock, self.k)  # fmt: skip
        self._state = kernel_args(state)
        # the FK result of the last update (its arrays are the estimator's: copy to keep)
        self._result = FKResult(self._fk_p, self._fk_R, 0.0, 0, FKStatus.CONVERGED)

    def apply_calibration(self, theta_zero: FloatArray, drum_scale: FloatArray) -> None:
        """A calibration record's offsets: cable i's unstretched length is ``l_home_i`` where
        its motor reads ``theta_zero_i`` (rad), and its drum pays out ``drum_scale_i`` times
        the config's r/G: ``l0 = l_zero − (r/G)·s·θ`` with ``l_zero = l_home + (r/G)·s·θ_zero``
        (docs/homing.md)."""
        np.multiply(self.nominal_drum_ratio, drum_scale, out=self.drum_ratio)
        np.multiply(self.drum_ratio, theta_zero, out=self.l_zero)
        self.l_zero += self.l_home

    def reset(self, position: FloatArray, rotation: FloatArray) -> None:
        self.position[:] = position
        self.rotation[:] = rotation
        self.velocity[:] = 0.0
        self.omega[:] = 0.0
        self._clock[0] = -math.inf

    def update(
        self,
        t: float,
        theta: FloatArray,
        tensions: FloatArray,
        theta_rate: FloatArray | None = None,
        age: FloatArray | None = None,
    ) -> FKResult:
        """New pose and twist from motor angles ``theta`` (rad) read at time ``t`` (s), the
        tensions (N) the cables carry, and optionally the motor velocities ``theta_rate``
        (rad/s) and the age of each drive's feedback ``age`` (s). Never raises. One compiled
        call (``estimate_kernel``): in numpy the ~40 small operations cost ~60 µs a cycle."""
        lag = theta_rate is not None and age is not None
        estimate_kernel(
            t,
            theta,
            tensions,
            theta_rate if lag else theta,
            age if lag else theta,
            lag,
            self.l_zero,
            self.drum_ratio,
            self._law,
            self.fk_cables,
            self.fk.data.arrays,
            self.fk.limits,
            self.fk.work,
            self._scratch,
            self.kin.arrays,
            self._state,
        )
        res = self._result
        # plain floats and a table: a numpy scalar and the enum's call each built objects
        info = self._info
        res.residual, res.iterations = info.item(0), int(info.item(1))
        res.status = _FK_STATUS[int(info.item(2))]
        self.last_fk = res
        return res


# each FKStatus by its code: the kernel's code read without calling the enum
_FK_STATUS = tuple(sorted(FKStatus))
# FKStatus codes for the compiled kernel
CONVERGED, MAX_ITERATIONS, INCONSISTENT = (
    int(FKStatus.CONVERGED),
    int(FKStatus.MAX_ITERATIONS),
    int(FKStatus.INCONSISTENT),
)


class FKScratch(NamedTuple):
    """The estimator's working arrays: angles brought to one instant (rad), all cables'
    lengths (m), the FK cables' lengths and residuals (m), FK's pose and ``info``, the
    rotation since the last pose ``dR`` and its rotation vector ``w`` (rad)."""

    th: np.ndarray
    lengths: np.ndarray
    fk_lengths: np.ndarray
    res: np.ndarray
    p: np.ndarray
    R: np.ndarray
    info: np.ndarray
    dR: np.ndarray
    w: np.ndarray


class EstimateState(NamedTuple):
    """What the estimate keeps between cycles: pose (m; rotation), twist (m/s, rad/s, base
    frame), ``clock`` = [last sample instant (s), 2π f_c of the velocity filter], and each
    cable's stiffness ``k`` (N/m) at the pose."""

    position: np.ndarray
    rotation: np.ndarray
    velocity: np.ndarray
    omega: np.ndarray
    clock: np.ndarray
    k: np.ndarray


@cycle_kernel
def estimate_kernel(
    t, theta, tensions, rate, age, lag, l_zero, drum_ratio, law, fk_cables, fk_kin, limits,
    fk_work, scratch, kin, state,
):  # pragma: no cover - compiled  # fmt: skip
    """``Estimator.update`` (see the module docstring for the steps): angles brought to the
    newest sample's instant when ``lag``, lengths under ``tensions`` (the cable law ``law``),
    the forward kinematics of the ``fk_cables`` (``fk_kin``, ``limits``) warm-started from the
    state's pose, the filtered twist, and the inverse kinematics (``kin``) and each cable's
    stiffness at the new pose, into ``state``."""
    th, lengths, fk_lengths, res, p, R, info, dR, w = scratch
    position, rotation, velocity, omega, clock, k = state
    m = theta.shape[0]
    shift = 0.0
    for i in range(m):
        th[i] = theta[i]
    if lag:
        newest = math.inf
        finite_rate = True
        for i in range(m):
            newest = min(newest, age[i])
            finite_rate = finite_rate and math.isfinite(rate[i])
        if finite_rate and math.isfinite(newest):
            # a drive never heard from has an infinite age but a zero velocity: no shift
            for i in range(m):
                th[i] += min(age[i] - newest, 0.1) * rate[i]
            shift = newest
    t = t - shift
    for i in range(m):
        l0 = l_zero[i] - drum_ratio[i] * th[i]
        lengths[i] = l0 + tensions[i] * compliance_at(law, i, l0)
    for j in range(fk_cables.shape[0]):
        fk_lengths[j] = lengths[fk_cables[j]]
    copy_pose(position, rotation, p, R)
    fk_kernel(fk_kin, fk_lengths, p, R, limits, res, info, fk_work)
    status = int(info[2])
    if status != CONVERGED and status != MAX_ITERATIONS and status != INCONSISTENT:
        return
    dt = t - clock[0]
    if 0.0 < dt < 0.5:
        a = 1.0 - math.exp(-clock[1] * dt)
        for j in range(3):
            velocity[j] += a * ((p[j] - position[j]) / dt - velocity[j])
        rotation_since(R, rotation, dR)
        log_so3_kernel(dR, w)
        for j in range(3):
            omega[j] += a * (w[j] / dt - omega[j])
    if dt > 0.0:
        clock[0] = t
    copy_pose(p, R, position, rotation)
    ik_kernel(kin, position, rotation)
    stiffness_kernel(kin[9], law, k)  # KinArrays.length
