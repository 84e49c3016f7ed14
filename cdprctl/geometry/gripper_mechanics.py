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

from cdprctl.core.numerics import cycle_kernel
from cdprctl.core.rotation import FloatArray

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
def _turn(R, v, i, out):  # pragma: no cover - compiled
    """``out`` ← ``R v[i]`` (3,): a platform-frame row of ``v`` in the base frame."""
    for a in range(3):
        out[a] = R[a, 0] * v[i, 0] + R[a, 1] * v[i, 1] + R[a, 2] * v[i, 2]


@cycle_kernel
def _jaw_loads_kernel(
    p_b, L1_b, k_b, mass, g, R, acc, vel, w, par, p, L1, k, f
):  # pragma: no cover - compiled
    """``w`` (6,) ← the jaws' loads on the main body (N, N·m about P, base frame) and ``par``
    (N) ← the part along each guide that ``jB`` carries: each jaw's weight under the
    effective gravity ``g − a_j`` (d'Alembert), ``a_j = a + α × r + ω × (ω × r)`` the
    acceleration of the jaw at ``r = R (p_j + L1_j)`` moving with the platform (``acc``,
    ``vel``: linear then angular, base frame), as a weight splits (Sensors 2019, eq. (26),
    (27), (35)): all of it through ``p``, the part across the guide through ``L1`` too.
    ``p``, ``L1``, ``k``, ``f``: (3,) scratch."""
    for a in range(6):
        w[a] = 0.0
    ox, oy, oz = vel[3], vel[4], vel[5]
    ax, ay, az = acc[3], acc[4], acc[5]
    for j in range(p_b.shape[0]):
        _turn(R, p_b, j, p)
        _turn(R, L1_b, j, L1)
        _turn(R, k_b, j, k)
        rx, ry, rz = p[0] + L1[0], p[1] + L1[1], p[2] + L1[2]
        # ω × r, then ω × (ω × r)
        vx, vy, vz = oy * rz - oz * ry, oz * rx - ox * rz, ox * ry - oy * rx
        cx, cy, cz = oy * vz - oz * vy, oz * vx - ox * vz, ox * vy - oy * vx
        f[0] = mass[j] * (g[0] - acc[0] - (ay * rz - az * ry) - cx)
        f[1] = mass[j] * (g[1] - acc[1] - (az * rx - ax * rz) - cy)
        f[2] = mass[j] * (g[2] - acc[2] - (ax * ry - ay * rx) - cz)
        fk = f[0] * k[0] + f[1] * k[1] + f[2] * k[2]
        q0, q1, q2 = f[0] - fk * k[0], f[1] - fk * k[1], f[2] - fk * k[2]  # across the guide
        par[j] = -fk
        w[0] += f[0]
        w[1] += f[1]
        w[2] += f[2]
        w[3] += p[1] * f[2] - p[2] * f[1] + L1[1] * q2 - L1[2] * q1
        w[4] += p[2] * f[0] - p[0] * f[2] + L1[2] * q0 - L1[0] * q2
        w[5] += p[0] * f[1] - p[1] * f[0] + L1[0] * q1 - L1[1] * q0


_AT_REST = np.zeros(6)  # the platform's acceleration and velocity at rest


class GripperSet:
    """The grippers of a robot (``[[grippers]]``) as the controller and the simulator use them:
    which cables carry one, the weight wrench ``J_weight F_BW`` (eq. (32), (35), (46)) and the
    load ``jB`` carries, at a platform orientation."""

    def __init__(self, model: Any):
        gs = model.grippers
        self.n = len(gs)
        self.cables = np.array([g.cable for g in gs], dtype=np.int64)
        # platform frame, (n, 3): attachment p_j^M, jaw offset L1^M, guide k̂_M
        self._p = np.array([model.attachments[g.cable] for g in gs], float).reshape(self.n, 3)
        self._L1 = np.array([g.jaw_offset for g in gs], float).reshape(self.n, 3)
        self._k = np.array([g.guide_axis for g in gs], float).reshape(self.n, 3)
        self.k_a = np.array([model.cables[g.cable].stiffness or 0.0 for g in gs])
        self.k_b = np.array([g.k_b for g in gs])
        self.mass = np.array([g.jaw_mass for g in gs], float)  # kg
        self._g = np.asarray(model.gravity, float).copy()  # m/s², base frame
        # (3,) scratch of the jaws' kernel: p, L1, k̂ turned into the base frame, a jaw's force
        self._sp, self._sL1, self._sk, self._sf = (np.zeros(3) for _ in range(4))

    @property
    def weight(self) -> FloatArray:
        """N per jaw: ``F_BW``, its mass times the gravity's magnitude."""
        return self.mass * float(np.linalg.norm(self._g))

    def at_rest(self, R: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(``J_weight F_BW`` (6,: N, N·m, base frame, about ``P``), ``‖F∥_jBW‖`` (n,: N)) at
        orientation ``R``: the grippers' weights on the main body (Sensors 2019, eq. (35),
        (46)) and the part along each guide, which ``jB`` holds (eq. (26)-(27)); one call of
        :meth:`jaw_loads` at rest."""
        w, par = np.zeros(6), np.zeros(self.n)
        self.jaw_loads(R, _AT_REST, _AT_REST, w, par)
        return w, par

    def weight_wrench(self, R: FloatArray) -> FloatArray:
        """``J_weight F_BW`` of :meth:`at_rest`."""
        return self.at_rest(R)[0]

    def jaw_loads(
        self,
        R: FloatArray,
        acceleration: FloatArray,
        velocity: FloatArray,
        wrench: FloatArray,
        parallel: FloatArray,
    ) -> None:
        """The jaws moving with the platform at orientation ``R``, desired ``acceleration`` and
        ``velocity`` (6,: m/s², rad/s², m/s, rad/s, base frame): ``wrench`` (6,) ← their
        weight and inertia on the main body (N, N·m about ``P``, base frame; at rest
        :meth:`weight_wrench`), ``parallel`` (n,) ← the part along each guide, which ``jB``
        carries (N; at rest :meth:`parallel_load`). Compiled, into the given arrays: the
        control cycle's feed-forward (``_jaw_loads_kernel``)."""
        if not self.n:
            wrench[:] = 0.0
            return
        _jaw_loads_kernel(
            self._p, self._L1, self._k, self.mass, self._g, R, acceleration, velocity, wrench,
            parallel, self._sp, self._sL1, self._sk, self._sf,
        )  # fmt: skip

    def parallel_load(self, R: FloatArray) -> FloatArray:
        """``‖F∥_jBW‖`` of :meth:`at_rest`."""
        return self.at_rest(R)[1]

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
