"""The reconfigurable end-effector's jaws on the platform, compiled (numba): one explicit step
of platform and jaws together by Kane's method, called by ``physics.physics_kernel``. A module
of its own: numba keys its cache by file, so an edit of the cable and winch step (each mutant
of a mutation session) recompiles that step only."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit


class Jaws(NamedTuple):
    """The reconfigurable end-effector's jaws (``CdprPlant._init_grippers`` has the units)."""

    of_cable: np.ndarray
    cable: np.ndarray
    mass: np.ndarray
    jaw0: np.ndarray
    axis: np.ndarray
    friction: np.ndarray
    friction_velocity: float
    travel_max: np.ndarray
    k_jb: np.ndarray
    c_jb: np.ndarray
    k_stop: np.ndarray
    c_stop: np.ndarray
    object_travel: np.ndarray
    k_contact: np.ndarray
    c_contact: np.ndarray


class JawState(NamedTuple):
    """Travel (m), speed (m/s), jB's tension (N), the object's force on the jaw (N)."""

    travel: np.ndarray
    speed: np.ndarray
    jb_tension: np.ndarray
    contact_force: np.ndarray


@njit(cache=True)
def jaw_dynamics(
    dt, P, R, com_pos, v, w, F, Mc, mass, Iw, g, rbT, jaws, jaw_state
):  # pragma: no cover - compiled
    """Platform and jaws together (Kane's method): generalised speeds ``u = [v_COM, ω, q̇_j]``,
    jaw velocity ``v_j = v + ω × r_j + q̇_j k_j`` (``k_j`` the guide, ``r_j`` COM → jaw), so
    ``(M_b + Σ m_j J_jᵀJ_j) u̇ = Q − Σ m_j J_jᵀ (ω×(ω×r_j) + 2 ω×q̇_j k_j)``; the guide's
    reactions do no work and drop out. Advances ``v``, ``ω``, ``q̇`` and ``q`` by ``dt``.
    ``F``/``Mc``: force and moment (about the COM, Euler term included) on the platform from
    the cables, gravity and the external wrench; jB pulls the jaw along ``k_j`` and the pulley
    at the cable's attachment along ``−k_j``; the object, the stops and the friction act
    between jaw and platform along the guide. ``jaws``/``jaw_state``: ``Jaws``, ``JawState``."""
    (_, g_cable, g_mass, g_jaw0, g_axis, g_fric, g_fric_v, g_qmax, _, _, g_kstop, g_cstop,
     g_L21, g_kc, g_cc) = jaws  # fmt: skip
    q, qd, g_tb, g_fc = jaw_state
    ng = g_mass.shape[0]
    n = 6 + ng
    A = np.zeros((n, n))
    Q = np.zeros(n)
    for a in range(3):
        A[a, a] = mass
        Q[a] = F[a]
        Q[3 + a] = Mc[a]
        for b in range(3):
            A[3 + a, 3 + b] = Iw[a, b]
    for j in range(ng):
        i = g_cable[j]
        k = R @ g_axis[j]
        r = P + R @ g_jaw0[j] + q[j] * k - com_pos
        mj = g_mass[j]
        # pulley at the attachment: −t_B k on the platform
        tb = g_tb[j]
        y = np.empty(3)
        for a in range(3):
            y[a] = rbT[a, i] + P[a] - com_pos[a]  # rbT: R b_i, from P
            Q[a] -= tb * k[a]
        Q[3] -= y[1] * tb * k[2] - y[2] * tb * k[1]
        Q[4] -= y[2] * tb * k[0] - y[0] * tb * k[2]
        Q[5] -= y[0] * tb * k[1] - y[1] * tb * k[0]
        # forces on the jaw: gravity and t_B along k, through J_jᵀ = [I; [r]×; kᵀ]
        f = np.empty(3)
        for a in range(3):
            f[a] = mj * g[a] + tb * k[a]
        # velocity-product acceleration c = ω×(ω×r) + 2 ω×(q̇ k), as forces −m c
        wr = np.cross(w, r)
        c = np.cross(w, wr) + 2.0 * qd[j] * np.cross(w, k)
        for a in range(3):
            f[a] -= mj * c[a]
        rf = np.cross(r, f)
        for a in range(3):
            Q[a] += f[a]
            Q[3 + a] += rf[a]
        Q[6 + j] += f[0] * k[0] + f[1] * k[1] + f[2] * k[2]
        # along the guide, between jaw and platform: object, end stops, friction
        s, g_fc[j] = _guide_force(q[j], qd[j], g_L21[j], g_kc[j], g_cc[j], g_kstop[j],
                                  g_cstop[j], g_qmax[j], g_fric[j], g_fric_v)  # fmt: skip
        Q[6 + j] += s
        _add_jaw_mass(A, 6 + j, mj, r, k)
    udot = np.linalg.solve(A, Q)
    for a in range(3):
        v[a] += udot[a] * dt
        w[a] += udot[3 + a] * dt
    for j in range(ng):
        qd[j] += udot[6 + j] * dt
        q[j] += qd[j] * dt


@njit(cache=True)
def _guide_force(
    q, qd, free, kc, cc, kstop, cstop, qmax, fric, fric_v
):  # pragma: no cover - compiled
    """(N along the guide on the jaw, N of the object's contact): the object beyond the free
    travel ``free`` (m; a spring-damper ``kc``, ``cc`` that only pushes), the end stops at 0
    and ``qmax`` (``kstop``, ``cstop``), the Coulomb friction ``fric`` (smoothed over
    ``fric_v`` m/s); ``q`` (m), ``qd`` (m/s) the jaw's travel and speed."""
    s = 0.0
    fc = 0.0
    if q > free:
        fc = kc * (q - free) + cc * qd
        if fc < 0.0:
            fc = 0.0
    s -= fc
    if q < 0.0:
        st = -kstop * q - cstop * qd
        s += st if st > 0.0 else 0.0
    elif q > qmax:
        st = kstop * (q - qmax) + cstop * qd
        s -= st if st > 0.0 else 0.0
    s -= fric * math.tanh(qd / fric_v)
    return s, fc


@njit(cache=True)
def _add_jaw_mass(A, j, mj, r, k):  # pragma: no cover - compiled
    """``A`` += a jaw's ``m J_jᵀ J_j`` with ``J_j = [I, −[r]×, k e_j]`` (``j``: its
    generalised speed's index; ``mj`` kg, ``r`` m from the COM, ``k`` the guide)."""
    rr = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
    rk = np.cross(r, k)
    for a in range(3):
        A[a, a] += mj
        A[a, j] += mj * k[a]
        A[j, a] += mj * k[a]
        A[3 + a, j] += mj * rk[a]
        A[j, 3 + a] += mj * rk[a]
        for b in range(3):
            A[3 + a, 3 + b] += mj * ((rr if a == b else 0.0) - r[a] * r[b])
    # the −[r]× block and its transpose: (−[r]×)[a, b] = ε_abc r_c
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        A[a, 3 + b] += mj * r[c]
        A[a, 3 + c] -= mj * r[b]
        A[3 + b, a] += mj * r[c]
        A[3 + c, a] -= mj * r[b]
    A[j, j] += mj
