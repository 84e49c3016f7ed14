"""The reconfigurable end-effector of Sensors 2019, 19, 3403, §2.4.

A gripper hangs on cable ``j`` through a compliant actuator: the cable splits into ``jA``, which
pulls the main body through a spring ``K_A``, and ``jB``, which runs over a small pulley to a
jaw on a 1-DOF linear guide fixed to the body. Both parts share the deformation ``δ_j``
(eq. (25)); the jaw closes on an object after the free travel ``L21`` and then squeezes it
through a spring ``K_B``.

* :func:`weight_matrix` — ``J_weight`` (eq. (27), (34)-(35)): the wrench of the grippers'
  weights on the main body, to add to the external wrench (eq. (46)).
* :func:`actuator_energy`, :func:`gripper_travel`, :func:`gripper_force`,
  :func:`energy_for_travel`, :func:`energy_for_force` — eq. (36)-(45) and their inverses.
* :func:`sense_grasp` — open / in contact / squeezing, from the actuator energy alone.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from cdprctl.rotation import FloatArray

UP = np.array([0.0, 0.0, 1.0])  # k̂: the vertical (base frame); gravity along −k̂


def weight_column(p_j: FloatArray, L1_j: FloatArray, guide_axis: FloatArray) -> FloatArray:
    """Column of ``J_weight`` for one gripper (Sensors 2019, eq. (35)), per newton of its
    weight: ``[−k̂ ; p_j × (−k̂) + L1_j × (−k̂ − Ω)]`` with ``Ω = −(k̂·k̂_M) k̂_M`` (eq. (27)).

    ``p_j`` (m): where cable j acts on the body, relative to ``P``, base frame; ``L1_j`` (m):
    from there to the jaw, base frame; ``guide_axis``: the guide's unit vector ``k̂_M``, base
    frame. (The paper prints +1 in the force row of its numeric J_weight; eq. (35) gives −1,
    which its F*_ext uses.)
    """
    kM = guide_axis / np.linalg.norm(guide_axis)
    omega = -float(UP @ kM) * kM
    force = -UP
    moment = np.cross(p_j, -UP) + np.cross(L1_j, -UP - omega)
    return np.concatenate([force, moment])


def weight_matrix(
    R: FloatArray, p_body: list[FloatArray], L1_body: list[FloatArray], guide_body: FloatArray
) -> FloatArray:
    """``J_weight`` (6 × grippers) at orientation ``R`` (platform → base) from body-frame
    geometry: ``p_j = R p_j^M``, ``L1_j = R L1_j^M`` (Sensors 2019 §3.2), ``k̂_M = R guide``."""
    kM = R @ guide_body
    cols = [weight_column(R @ p, R @ L1, kM) for p, L1 in zip(p_body, L1_body, strict=True)]
    return np.stack(cols, axis=1)


@dataclass(frozen=True)
class GripperParams:
    """Parameters of one compliant actuator and its gripper (SI)."""

    k_a: float  # N/m, spring K_A between cable j and the main body
    k_b: float  # N/m, squeezing spring K_B of the jaw
    f_parallel: float  # N, ‖F∥_jBW‖ + F_jBA: jaw weight along jB plus friction (eq. (26))
    free_travel: float  # m, L21: deformation at which the jaw meets the object
    u_min: float = 0.0  # J, energy reference of the mechanism (eq. (36))


def actuator_energy(g: GripperParams, delta: float) -> float:
    """Energy (J) the actuator of cable j holds at deformation ``delta`` (m).

    Open (δ <= L21), eq. (36): ``U = K_A δ²/2 + U_min + F∥ δ``; closed (δ > L21), eq. (40):
    ``U = K_A δ²/2 + U_min + K_B (δ − L21)²/2 + F∥ L21``.
    """
    u_a = 0.5 * g.k_a * delta * delta
    if delta <= g.free_travel:
        return u_a + g.u_min + g.f_parallel * delta
    s = delta - g.free_travel
    return u_a + g.u_min + 0.5 * g.k_b * s * s + g.f_parallel * g.free_travel


def gripper_travel(g: GripperParams, energy: float) -> float:
    """Deformation δ (m), i.e. the jaw's travel, for an actuator energy ``energy`` (J).

    Open: the root of eq. (36), ``δ = (−F∥ + √(F∥² + 2 K_A (U − U_min)))/K_A`` (eq. (37) prints
    ``U + U_min``; eq. (36) gives the minus sign). Closed: eq. (41)-(42).
    """
    F = g.f_parallel
    if energy <= actuator_energy(g, g.free_travel):
        disc = F * F + 2.0 * g.k_a * (energy - g.u_min)
        return (-F + math.sqrt(max(disc, 0.0))) / g.k_a
    kb, L = g.k_b, g.free_travel
    delta_ = F * L + 0.5 * kb * L * L - energy + g.u_min  # eq. (42)
    disc = (kb * L) ** 2 - 2.0 * (g.k_a + kb) * delta_
    return (kb * L + math.sqrt(max(disc, 0.0))) / (g.k_a + kb)  # eq. (41)


def gripper_force(g: GripperParams, delta: float) -> float:
    """Squeezing force (N) at deformation ``delta``: ``K_B (δ − L21)`` once closed, else 0
    (eq. (43); its second case prints ``δ > L21`` for ``δ <= L21``)."""
    return g.k_b * (delta - g.free_travel) if delta > g.free_travel else 0.0


def energy_for_travel(g: GripperParams, delta: float) -> float:
    """Inverse of :func:`gripper_travel`: the actuator energy (J) for a jaw travel (m)."""
    return actuator_energy(g, delta)


def energy_for_force(g: GripperParams, force: float) -> float:
    """Actuator energy (J) for a squeezing force (N): ``δ = L21 + F/K_B`` in eq. (40)."""
    return actuator_energy(g, g.free_travel + max(force, 0.0) / g.k_b)


def energy_range(g: GripperParams, u_a_min: float, u_a_max: float) -> tuple[float, float]:
    """Actuator energy bounds (J) for the spring-A energy range ``[u_a_min, u_a_max]`` (J)
    that the tension distribution allows (eq. (38)-(39) open; (44)-(45) closed)."""
    d_lo = math.sqrt(2.0 * u_a_min / g.k_a)
    d_hi = math.sqrt(2.0 * u_a_max / g.k_a)
    return actuator_energy(g, d_lo), actuator_energy(g, d_hi)


class GraspState(enum.StrEnum):
    OPEN = "open"
    CONTACT = "contact"
    SQUEEZING = "squeezing"


@dataclass(frozen=True)
class GraspEstimate:
    state: GraspState
    travel: float  # m
    force: float  # N


def sense_grasp(g: GripperParams, energy: float, contact_band: float = 1e-3) -> GraspEstimate:
    """Gripper state from the actuator energy alone (Sensors 2019 §2.4, "energy measurement
    from the actuators allows the grasping state to be sensed"): the travel by eq. (37)/(41),
    the force by eq. (43). ``contact_band`` (m): travel past ``L21`` still called contact."""
    delta = gripper_travel(g, energy)
    force = gripper_force(g, delta)
    if delta < g.free_travel - 1e-12:
        return GraspEstimate(GraspState.OPEN, delta, 0.0)
    if delta <= g.free_travel + contact_band:
        return GraspEstimate(GraspState.CONTACT, delta, force)
    return GraspEstimate(GraspState.SQUEEZING, delta, force)


@njit(cache=True)
def _weight_wrench_kernel(p_b, L1_b, k_b, weight, up, R, w):  # pragma: no cover - compiled
    """Σ_j F_jBW [−k̂; p_j × (−k̂) + L1_j × (−k̂ − Ω_j)] with p, L1, k̂_M turned by R
    (Sensors 2019, eq. (27), (35))."""
    for j in range(p_b.shape[0]):
        p = R @ p_b[j]
        L1 = R @ L1_b[j]
        k = R @ k_b[j]
        c = k[0] * up[0] + k[1] * up[1] + k[2] * up[2]
        f = weight[j]
        # −k̂ − Ω = −up + (up·k) k
        q0, q1, q2 = -up[0] + c * k[0], -up[1] + c * k[1], -up[2] + c * k[2]
        d0, d1, d2 = -up[0], -up[1], -up[2]
        w[0] += f * d0
        w[1] += f * d1
        w[2] += f * d2
        w[3] += f * (p[1] * d2 - p[2] * d1 + L1[1] * q2 - L1[2] * q1)
        w[4] += f * (p[2] * d0 - p[0] * d2 + L1[2] * q0 - L1[0] * q2)
        w[5] += f * (p[0] * d1 - p[1] * d0 + L1[0] * q1 - L1[1] * q0)


class GripperSet:
    """The grippers of a robot (``[[grippers]]``) as the controller and the simulator use them:
    which cables carry one, the weight wrench ``J_weight F_BW`` (eq. (32), (35), (46)) and the
    load ``jB`` carries, at a platform orientation."""

    def __init__(self, model: Any):
        gs = model.grippers
        self.n = len(gs)
        self.cables = np.array([g.cable for g in gs], dtype=np.int64)
        self.weight = np.array([g.jaw_mass for g in gs]) * float(np.linalg.norm(model.gravity))
        # platform frame, (n, 3): attachment p_j^M, jaw offset L1^M, guide k̂_M
        self._p = np.array([model.attachments[g.cable] for g in gs], float).reshape(self.n, 3)
        self._L1 = np.array([g.jaw_offset for g in gs], float).reshape(self.n, 3)
        self._k = np.array([g.guide_axis for g in gs], float).reshape(self.n, 3)
        self.k_a = np.array([model.cables[g.cable].stiffness or 0.0 for g in gs])
        self.k_b = np.array([g.k_b for g in gs])
        self.up = -np.asarray(model.gravity, float) / max(
            float(np.linalg.norm(model.gravity)), 1e-12
        )

    def weight_wrench(self, R: FloatArray) -> FloatArray:
        """``J_weight F_BW`` (N, N·m, base frame, about ``P``) at orientation ``R``: the
        grippers' weights on the main body (Sensors 2019, eq. (35), (46)); the columns of
        :func:`weight_column`, compiled (it runs every control cycle)."""
        w = np.zeros(6)
        if self.n:
            _weight_wrench_kernel(self._p, self._L1, self._k, self.weight, self.up, R, w)
        return w

    def parallel_load(self, R: FloatArray) -> FloatArray:
        """``‖F∥_jBW‖`` (N) per gripper: the part of the jaw's weight along its guide, which
        ``jB`` holds (eq. (26)-(27))."""
        return self.weight * ((self._k @ R.T) @ self.up)

    def spring_wrench(self, W: FloatArray, wrench: FloatArray, jb_load: FloatArray) -> FloatArray:
        """The wrench the springs ``jA`` must give when the cables give ``wrench`` and each
        gripper's ``jB`` carries ``jb_load`` (N): ``τ_j = τ_jA + τ_jB`` (eq. (26)), so
        ``W τ_A = wrench − Σ_j τ_jB W_j``. The tension distribution works on ``τ_A``: its
        limits and energies are the springs' (Sensors 2019 §3.2 imposes δ_8A)."""
        if self.n == 0:
            return wrench
        return wrench - W[:, self.cables] @ jb_load

    def params(self, i: int, free_travel: float) -> GripperParams:
        """The closed-form parameters of gripper ``i`` (eq. (36)-(45)) at orientation-free
        load (vertical guide): ``F∥ = F_BW``, with ``free_travel`` (m) the ``L21`` in use."""
        return GripperParams(
            k_a=float(self.k_a[i]),
            k_b=float(self.k_b[i]),
            f_parallel=float(self.weight[i]),
            free_travel=free_travel,
        )
