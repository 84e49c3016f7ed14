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

from cdprctl.forward_kinematics import FKResult, FKStatus, ForwardKinematics
from cdprctl.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel
from cdprctl.rotation import FloatArray, log_so3


class Estimator:
    def __init__(self, model: RobotModel):
        self.model = model
        c = model.cables
        self.drum_ratio = np.array([x.winch.drum_radius / x.winch.gear_ratio for x in c])
        kin = KinematicsData(model)
        inverse_kinematics(model, kin, model.home.position, model.home.rotation)
        self.l_home = kin.length.copy()
        # compliance per cable: 1/k_fixed, or (l0 + l_w)/(E S), plus the series spring's 1/k_s
        self.inv_k_fixed = np.array(
            [1.0 / x.stiffness if x.stiffness is not None else 0.0 for x in c]
        )
        self.inv_es = np.array(
            [
                0.0
                if x.stiffness is not None
                else 1.0 / ((x.youngs_modulus or 1.0) * (x.cross_section or 1.0))
                for x in c
            ]
        )
        self.inv_spring = np.array(
            [1.0 / x.spring_stiffness if x.spring_stiffness else 0.0 for x in c]
        )
        self.l_winch = np.array([x.length_to_winch for x in c])
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
        self._stamp = -math.inf
        self._alpha_fc = 2.0 * math.pi * model.control.velocity_filter
        self._theta = np.zeros(model.n_cables)  # rad, the angles brought to one instant
        self._lag = np.zeros(model.n_cables)  # s, then rad: each cable's shift to that instant

    def cable_lengths(self, theta: FloatArray, tensions: FloatArray) -> FloatArray:
        """Geometric lengths (m) from motor angles (rad) and the tensions (N) they carry."""
        l0 = self.l_home - self.drum_ratio * theta
        return l0 + tensions * (
            self.inv_k_fixed + self.inv_es * (l0 + self.l_winch) + self.inv_spring
        )

    def stiffness(self, lengths: FloatArray) -> FloatArray:
        """Axial stiffness k_i (N/m) at geometric lengths (m), vectorised
        (``RobotModel.cable_stiffness`` loops over cables)."""
        return 1.0 / (self.inv_k_fixed + self.inv_es * (lengths + self.l_winch) + self.inv_spring)

    def reset(self, position: FloatArray, rotation: FloatArray) -> None:
        self.position[:] = position
        self.rotation[:] = rotation
        self.velocity[:] = 0.0
        self.omega[:] = 0.0
        self._stamp = -math.inf

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
        (rad/s) and the age of each drive's feedback ``age`` (s). Never raises."""
        th = self._theta
        th[:] = theta
        if theta_rate is not None and age is not None and np.all(np.isfinite(theta_rate)):
            newest = float(age.min())
            if math.isfinite(newest):
                # a drive never heard from has an infinite age but a zero velocity: no shift
                lag = self._lag
                np.subtract(age, newest, out=lag)
                np.minimum(lag, 0.1, out=lag)
                lag *= theta_rate
                th += lag
                t = t - newest
        self.lengths[:] = self.cable_lengths(th, tensions)
        lengths = self.lengths[self.fk_cables] if self.model.grippers else self.lengths
        res = self.fk.solve(lengths, self.position, self.rotation)
        self.last_fk = res
        if res.status in (FKStatus.CONVERGED, FKStatus.MAX_ITERATIONS, FKStatus.INCONSISTENT):
            dt = t - self._stamp
            if 0.0 < dt < 0.5:
                a = 1.0 - math.exp(-self._alpha_fc * dt)
                self.velocity += a * ((res.position - self.position) / dt - self.velocity)
                self.omega += a * (log_so3(res.rotation @ self.rotation.T) / dt - self.omega)
            if dt > 0.0:
                self._stamp = t
            self.position[:] = res.position
            self.rotation[:] = res.rotation
            inverse_kinematics(self.model, self.kin, self.position, self.rotation)
        return res
