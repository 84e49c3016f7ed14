"""Stiffness matrix of the platform, K = Kp + Ka (Picard et al. 2020, eq. (3)-(4)).

Sign convention: ``K = δw_e/δX``. A small change ``δw_e`` of the external wrench applied to the
platform (N, N·m; base frame; moments about ``P``) displaces it, the winches being locked, by the
screw ``δX = [δp, δφ] = K⁻¹ δw_e`` (m, rad; base frame; rotation vector applied on the left).
Equivalently ``K = −∂(W t)/∂X`` with ``δt_i = k_i δl_i``: ``K`` is positive definite for a stable
equilibrium.

* ``Kp = W diag(k) Wᵀ`` (passive part, eq. (4) top): cable elasticity ``k_i`` (N/m).
* ``Ka`` (active or geometric part, eq. (4) bottom): the change of the cable directions at
  constant tensions ``t_i``, with ``l_i`` the free length.

With swivel pulleys, ``u_i`` and ``l_i`` refer to the moving tangent point; the motion of that
point along the wheel is neglected in ``Ka`` (as the paper neglects pulleys).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics

if TYPE_CHECKING:
    from cdprctl.model.robot import RobotModel


def cable_stiffnesses(model: RobotModel, data: KinematicsData) -> FloatArray:
    """Axial stiffness ``k_i`` (N/m) of each cable at the pose of ``data`` (``k = E·S/l``)."""
    return model.cable_stiffness(data.length)


def passive_stiffness(data: KinematicsData, k: FloatArray) -> FloatArray:
    """``Kp = W diag(k) Wᵀ`` (Picard et al. 2020, eq. (4)), 6×6."""
    return (data.W * k) @ data.WT


def active_stiffness_per_cable(data: KinematicsData) -> FloatArray:
    """(m, 6, 6): the active stiffness of each cable per newton of its tension, so that
    ``Ka(t) = Σ t_i Ka_i`` (Picard et al. 2020, eq. (4)). With ``P_i = (I − u_i u_iᵀ)/l_i`` and
    ``B̂_i = [R b_i]×``::

        Ka_i = −[ −P_i        P_i B̂_i
                  −B̂_i P_i   (Û_i + B̂_i P_i) B̂_i ]
    """
    u = data.u
    inv_l = 1.0 / data.free_length
    P = np.eye(3)[None, :, :] - u[:, :, None] * u[:, None, :]
    P *= inv_l[:, None, None]
    Bh = _skew_stack(data.rb)
    Uh = _skew_stack(u)
    BP = Bh @ P
    out = np.empty((data.n_cables, 6, 6))
    out[:, :3, :3] = P
    out[:, :3, 3:] = -(P @ Bh)
    out[:, 3:, :3] = BP
    out[:, 3:, 3:] = -((Uh + BP) @ Bh)
    return out


def active_stiffness_weighted(data: KinematicsData, T: FloatArray) -> FloatArray:
    """``Ka`` for several tension vectors at once: ``T`` (n, m) → (n, 6, 6).

    The same matrix as :func:`active_stiffness_per_cable` summed with weights ``t``, from
    sums over cables instead of m 6×6 products (the SOTDA needs three per cycle). With
    ``w_i = t_i/l_i``, ``m_i = b_i × u_i`` (the moment rows of W) and the identities
    ``uᵀ B̂ = −mᵀ``, ``Û B̂ = b uᵀ − (u·b) I``, ``B̂ B̂ = b bᵀ − |b|² I``::

        K11 = Σw I − Σ w u uᵀ          K12 = −[Σ w b]× − Σ w u mᵀ
        K21 = [Σ w b]× − Σ w m uᵀ      K22 = −Σ t b uᵀ + (Σ t u·b) I
                                               − Σ w (b bᵀ − |b|² I + m mᵀ)
    """
    out = np.empty((T.shape[0], 6, 6))
    _ka_weighted(data.uT, data.W, data.rbT, data.free_length, np.ascontiguousarray(T), out)
    return out


@njit(cache=True)
def _ka_weighted(uT, W, rbT, free_len, T, out):  # pragma: no cover - compiled
    n, m = T.shape
    for a in range(n):
        K = out[a]
        K[:, :] = 0.0
        sw = 0.0
        s_tub = 0.0
        s_wbb = 0.0
        wbx = wby = wbz = 0.0
        for i in range(m):
            t = T[a, i]
            w = t / free_len[i]
            u0, u1, u2 = uT[0, i], uT[1, i], uT[2, i]
            m0, m1, m2 = W[3, i], W[4, i], W[5, i]
            b0, b1, b2 = rbT[0, i], rbT[1, i], rbT[2, i]
            sw += w
            s_tub += t * (u0 * b0 + u1 * b1 + u2 * b2)
            s_wbb += w * (b0 * b0 + b1 * b1 + b2 * b2)
            wbx += w * b0
            wby += w * b1
            wbz += w * b2
            u = (u0, u1, u2)
            mm = (m0, m1, m2)
            b = (b0, b1, b2)
            for r in range(3):
                for c in range(3):
                    K[r, c] -= w * u[r] * u[c]  # −Σ w u uᵀ
                    K[r, 3 + c] -= w * u[r] * mm[c]  # −Σ w u mᵀ
                    K[3 + r, c] -= w * mm[r] * u[c]  # −Σ w m uᵀ
                    K[3 + r, 3 + c] -= t * b[r] * u[c] + w * (b[r] * b[c] + mm[r] * mm[c])
        for r in range(3):
            K[r, r] += sw
            K[3 + r, 3 + r] += s_tub + s_wbb
        # −[Σ w b]× in the upper right block, +[Σ w b]× in the lower left one
        K[0, 4] += wbz
        K[0, 5] -= wby
        K[1, 3] -= wbz
        K[1, 5] += wbx
        K[2, 3] += wby
        K[2, 4] -= wbx
        K[3, 1] -= wbz
        K[3, 2] += wby
        K[4, 0] += wbz
        K[4, 2] -= wbx
        K[5, 0] -= wby
        K[5, 1] += wbx


def active_stiffness(data: KinematicsData, t: FloatArray) -> FloatArray:
    """``Ka`` (Picard et al. 2020, eq. (4)), 6×6, for cable tensions ``t`` (N)."""
    return np.tensordot(t, active_stiffness_per_cable(data), axes=1)


def stiffness_matrix(
    model: RobotModel, data: KinematicsData, t: FloatArray, k: FloatArray | None = None
) -> FloatArray:
    """``K = Kp + Ka`` (Picard et al. 2020, eq. (3)-(4)) at the pose of ``data`` for tensions
    ``t`` (N); ``k`` (N/m) defaults to the model's cable stiffness at the current lengths."""
    if k is None:
        k = cable_stiffnesses(model, data)
    return passive_stiffness(data, k) + active_stiffness(data, t)


def _skew_stack(v: FloatArray) -> FloatArray:
    """(m, 3) vectors → (m, 3, 3) cross-product matrices."""
    m = v.shape[0]
    S = np.zeros((m, 3, 3))
    S[:, 0, 1] = -v[:, 2]
    S[:, 0, 2] = v[:, 1]
    S[:, 1, 0] = v[:, 2]
    S[:, 1, 2] = -v[:, 0]
    S[:, 2, 0] = -v[:, 1]
    S[:, 2, 1] = v[:, 0]
    return S


def lowest_mode(model: RobotModel) -> float:
    """rad/s: the platform's lowest natural frequency on its cables' passive stiffness at the
    home pose, ``√min eig(M⁻¹ Kp)`` with ``M = diag(m I, R I_c Rᵀ)`` about P (the COM's offset
    neglected): on rowc the near-planar y mode, 3.4 Hz."""
    from scipy.linalg import eigh

    data = KinematicsData(model)
    inverse_kinematics(model, data, model.home.position, model.home.rotation)
    Kp = passive_stiffness(data, cable_stiffnesses(model, data))
    R = model.home.rotation
    M = np.zeros((6, 6))
    M[:3, :3] = model.platform.mass * np.eye(3)
    M[3:, 3:] = R @ np.asarray(model.platform.inertia) @ R.T
    return float(np.sqrt(max(float(eigh(Kp, M, eigvals_only=True)[0]), 0.0)))
