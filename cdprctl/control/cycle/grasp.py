"""Grasp sensing from the drive side only: motor torque and position, no sensor on the
end-effector (Sensors 2019, 19, 3403, §2.4: "the energy measurement from the actuators allows
the grasping state to be sensed").

Per gripper cable ``j``, each cycle:

* the cable tension from the drive's measured torque, quasi-static:
  ``τ_j = (τ_m − b θ̇ − τ_c tanh(θ̇/ω_ε)) / (r/G)``;
* the actuator's deformation ``δ_j = l_j(X̂) − l0_j(θ)``: the geometric length at the estimated
  pose (found from the other cables) less the paid-out length (the cable is inextensible, all
  of ``δ`` is the spring ``K_A``; eq. (25));
* the squeeze force from the node's balance, eq. (26) with (43):
  ``F_BA = τ_j − K_A δ_j − ‖F∥_jBW‖`` (zero while the jaw is free), low-passed;
* the state with hysteresis: open → contact above ``contact_force`` → squeezing above
  ``squeeze_force``, open again below half of ``contact_force``; the contact travel
  ``L21 = δ − F_BA/K_B`` (eq. (43) inverted); the actuator energy by eq. (36) open, (40)
  closed, on demand (telemetry), not in the cycle.

The guide's friction (``F_jBA``) and the winch's static friction are inside ``F_BA``'s error:
the thresholds must stand above them (docs/gripper.md gives the measured accuracy).
"""

from __future__ import annotations

import math

import numpy as np

from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.gripper_mechanics import GraspState, GripperSet, actuator_energy


class GraspSensor:
    def __init__(
        self,
        grippers: GripperSet,
        period: float,
        cutoff: float = 5.0,
        contact_force: float = 6.0,
        squeeze_force: float = 15.0,
    ):
        self.gs = grippers
        n = grippers.n
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff * period)
        self.contact_force = contact_force  # N
        self.squeeze_force = squeeze_force  # N
        self.state = [GraspState.OPEN] * n
        self.force = np.zeros(n)  # N, estimated squeeze force F_BA
        self.travel = np.zeros(n)  # m, δ: the jaw's travel
        self.tension = np.zeros(n)  # N, cable tension from the motor torque
        self.contact_travel = np.full(n, math.nan)  # m, L21 once in contact
        self._primed = False

    def update(self, tension: FloatArray, delta: FloatArray, f_parallel: FloatArray) -> None:
        """``tension`` (N) and ``delta`` (m) of the gripper cables, ``f_parallel`` (N) the
        jaws' weight along their guides. Never raises; non-finite input keeps the last state."""
        if not (np.all(np.isfinite(tension)) and np.all(np.isfinite(delta))):
            return
        gs = self.gs
        raw = tension - gs.k_a * delta - f_parallel
        a = self.alpha if self._primed else 1.0
        self._primed = True
        self.force += a * (raw - self.force)
        self.tension += a * (tension - self.tension)
        self.travel += a * (delta - self.travel)
        for j in range(gs.n):
            f = float(self.force[j])
            s = self.state[j]
            if s is GraspState.OPEN and f > self.contact_force:
                s = GraspState.CONTACT
            elif s is not GraspState.OPEN and f < 0.5 * self.contact_force:
                s = GraspState.OPEN
            elif s is GraspState.CONTACT and f > self.squeeze_force:
                s = GraspState.SQUEEZING
            elif s is GraspState.SQUEEZING and f < self.contact_force:
                s = GraspState.CONTACT
            self.state[j] = s
            self.contact_travel[j] = (
                math.nan
                if s is GraspState.OPEN
                else float(self.travel[j]) - max(f, 0.0) / float(gs.k_b[j])
            )

    def reported_force(self) -> FloatArray:
        """N per gripper: the estimated squeeze, 0 while open (what telemetry shows)."""
        open_ = np.array([s is GraspState.OPEN for s in self.state], dtype=bool)
        return np.where(open_, 0.0, self.force)

    def energies(self) -> FloatArray:
        """J per gripper: the actuator energy at the sensed travel, eq. (36) open, eq. (40)
        closed at the sensed contact travel."""
        out = np.zeros(self.gs.n)
        for j in range(self.gs.n):
            L21 = float(self.contact_travel[j])
            p = self.gs.params(j, math.inf if math.isnan(L21) else L21)
            out[j] = actuator_energy(p, float(self.travel[j]))
        return out
