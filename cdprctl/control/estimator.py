"""Platform state from the winch encoders.

Motor angles → unstretched cable lengths (``l0 = l_home − (r/G) θ``: encoders calibrated at the
home pose, docs/simulator.md) → stretched lengths under the tensions the caller gives (the
controller passes feed-forward tensions, docs/control.md) → forward kinematics warm-started from
the last pose → twist by finite differences of successive poses through a first-order low-pass
filter (cut-off ``[control] velocity_filter`` Hz): ``v ← v + α (Δp/Δt − v)``,
``α = 1 − exp(−2π f_c Δt)``; the angular velocity from ``log(R_k R_(k−1)ᵀ)/Δt``. The poses
include the elastic stretch, so the platform's motion on its cables is seen too (a twist from the
motor rates, ``l̇ = −Wᵀ ẋ``, misses it and lost the damping of a lateral push in the lock-step
tests).

Feedback of different ages (a drive's frame a cycle late or lost on a lossy bus) is brought to
one instant, the newest sample's, by ``θ + θ̇ (age − age_min)`` before the forward kinematics,
and ``Δt`` is taken between sample instants, not read times: otherwise one late drive shifts the
pose by a cycle of that cable's motion and ``Δp/Δt`` spikes (tests/test_estimator.py: 0.05 m/s
and more at 0.3 m/s with one drive late every third cycle).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

from cdprctl.forward_kinematics import FKResult, FKStatus, ForwardKinematics, fk_kernel
from cdprctl.kinematics import KinematicsData, ik_kernel, inverse_kinematics
from cdprctl.model.robot import RobotModel
from cdprctl.numerics import cable_compliance, compliance_terms
from cdprctl.rotation import FloatArray, log_so3_kernel


class Estimator:
    def __init__(self, model: RobotModel):
        self.model = model
        c = model.cables
        self.drum_ratio = np.array([x.winch.drum_radius / x.winch.gear_ratio for x in c])
        kin = KinematicsData(model)
        inverse_kinematics(model, kin, model.home.position, model.home.rotation)
        self.l_home = kin.length.copy()
        # the cable law's terms per cable (cdprctl.numerics.cable_compliance)
        terms = np.array([compliance_terms(x) for x in c]).reshape(len(c), 4)
        self.inv_k_fixed, self.inv_es, self.l_winch, self.inv_spring = (
            np.ascontiguousarray(terms[:, j]) for j in range(4)
        )
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
        self._fk_lengths = np.zeros(len(self.fk_cables))  # m, the lengths FK works from
        self._fk_res = np.zeros(len(self.fk_cables))  # m, FK's length residuals
        self._fk_p = np.zeros(3)
        self._fk_R = np.eye(3)
        self._info = np.zeros(3)  # FK: RMS residual (m), iterations, FKStatus
        self.k = np.zeros(model.n_cables)  # N/m, each cable's at the estimated pose
        stiffness_kernel(
            self.l_home, self.inv_k_fixed, self.inv_es, self.l_winch, self.inv_spring, self.k
        )
        # the FK result of the last update (its arrays are the estimator's: copy to keep)
        self._result = FKResult(self._fk_p, self._fk_R, 0.0, 0, FKStatus.CONVERGED)

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
        fk, d, k = self.fk, self.fk.data, self.kin
        lag = theta_rate is not None and age is not None
        estimate_kernel(
            t,
            theta,
            tensions,
            theta_rate if lag else theta,
            age if lag else theta,
            lag,
            self.l_home,
            self.drum_ratio,
            self.inv_k_fixed,
            self.inv_es,
            self.l_winch,
            self.inv_spring,
            self.fk_cables,
            self._theta,
            self.lengths,
            self._fk_lengths,
            d.anchors,
            d.attachments,
            d.pulley_radius,
            d.pulley_axis,
            fk.tolerance,
            fk.step_tolerance,
            fk.max_iterations,
            fk.max_residual,
            d.rbT,
            d.exitT,
            d.cable_vectorsT,
            d.free_length,
            d.wrap_angle,
            d.length,
            d.W,
            self._fk_res,
            self._fk_p,
            self._fk_R,
            self._info,
            k.anchors,
            k.attachments,
            k.pulley_radius,
            k.pulley_axis,
            k.rbT,
            k.exitT,
            k.cable_vectorsT,
            k.free_length,
            k.wrap_angle,
            k.length,
            k.W,
            self.position,
            self.rotation,
            self.velocity,
            self.omega,
            self._clock,
            self.k,
        )
        res = self._result
        res.residual, res.iterations = float(self._info[0]), int(self._info[1])
        res.status = FKStatus(int(self._info[2]))
        self.last_fk = res
        return res


# FKStatus codes for the compiled kernel
CONVERGED, MAX_ITERATIONS, INCONSISTENT = (
    int(FKStatus.CONVERGED),
    int(FKStatus.MAX_ITERATIONS),
    int(FKStatus.INCONSISTENT),
)


@njit(cache=True)
def estimate_kernel(
    t,
    theta,
    tensions,
    rate,
    age,
    lag,
    l_home,
    drum_ratio,
    inv_k_fixed,
    inv_es,
    l_winch,
    inv_spring,
    fk_cables,
    th,
    lengths,
    fk_lengths,
    f_anchors,
    f_attach,
    f_pulley_r,
    f_pulley_axis,
    tol,
    step_tol,
    max_iter,
    max_residual,
    f_rbT,
    f_exitT,
    f_vT,
    f_free,
    f_wrap,
    f_length,
    f_W,
    f_res,
    p,
    R,
    info,
    anchors,
    attach,
    pulley_r,
    pulley_axis,
    rbT,
    exitT,
    vT,
    free_len,
    wrap,
    length,
    W,
    position,
    rotation,
    velocity,
    omega,
    clock,
    k,
):  # pragma: no cover - compiled
    """``Estimator.update`` (see the module docstring for the steps): angles brought to the
    newest sample's instant when ``lag``, lengths (``cable_lengths``), the forward kinematics
    of the ``fk_cables`` warm-started from ``position``/``rotation`` (``fk_kernel``, into
    ``p``, ``R`` and ``info`` = [RMS residual, iterations, FKStatus]), the filtered twist and
    the inverse kinematics at the new pose and there the cable stiffness ``k`` (N/m).
    ``clock`` = [last sample instant (s), 2π f_c]."""
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
        l0 = l_home[i] - drum_ratio[i] * th[i]
        lengths[i] = l0 + tensions[i] * cable_compliance(
            inv_k_fixed[i], inv_es[i], l_winch[i], inv_spring[i], l0
        )
    for j in range(fk_cables.shape[0]):
        fk_lengths[j] = lengths[fk_cables[j]]
    p[:] = position
    R[:, :] = rotation
    fk_kernel(
        f_anchors,
        f_attach,
        f_pulley_r,
        f_pulley_axis,
        fk_lengths,
        p,
        R,
        tol,
        step_tol,
        max_iter,
        f_rbT,
        f_exitT,
        f_vT,
        f_free,
        f_wrap,
        f_length,
        f_W,
        f_res,
        max_residual,
        info,
    )
    status = int(info[2])
    if status != CONVERGED and status != MAX_ITERATIONS and status != INCONSISTENT:
        return
    dt = t - clock[0]
    if 0.0 < dt < 0.5:
        a = 1.0 - math.exp(-clock[1] * dt)
        for j in range(3):
            velocity[j] += a * ((p[j] - position[j]) / dt - velocity[j])
        dR = R @ rotation.T
        w = np.empty(3)
        log_so3_kernel(dR, w)
        for j in range(3):
            omega[j] += a * (w[j] / dt - omega[j])
    if dt > 0.0:
        clock[0] = t
    position[:] = p
    rotation[:, :] = R
    ik_kernel(
        anchors,
        attach,
        pulley_r,
        pulley_axis,
        position,
        rotation,
        rbT,
        exitT,
        vT,
        free_len,
        wrap,
        length,
        W,
    )
    stiffness_kernel(length, inv_k_fixed, inv_es, l_winch, inv_spring, k)


@njit(cache=True)
def stiffness_kernel(lengths, inv_k_fixed, inv_es, l_winch, inv_spring, out):  # pragma: no cover
    """``out`` ← the axial stiffness k_i (N/m) of each cable at ``lengths`` (m)."""
    for i in range(lengths.shape[0]):
        out[i] = 1.0 / cable_compliance(
            inv_k_fixed[i], inv_es[i], l_winch[i], inv_spring[i], lengths[i]
        )
