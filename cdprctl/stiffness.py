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

from cdprctl.kinematics import KinematicsData
from cdprctl.rotation import FloatArray

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
    n = T.shape[0]
    X = data._x9  # rows [u; m; b]: (9, m)
    X[:3] = data.uT
    X[3:6] = data.W[3:]
    X[6:] = data.rbT
    Wt = T / data.free_length  # (n, m): w = t/l
    G = (Wt[:, None, :] * X[None]) @ X.T  # (n, 9, 9): Σ w x yᵀ for every pair of u, m, b
    BU = (T[:, None, :] * X[None, 6:]) @ X[:3].T  # (n, 3, 3): Σ t b uᵀ
    uu, um, mm, bb = G[:, :3, :3], G[:, :3, 3:6], G[:, 3:6, 3:6], G[:, 6:, 6:]
    sw = Wt.sum(axis=1)
    wb = Wt @ X[6:].T  # (n, 3): Σ w b
    skew = (wb @ _SKEW_GEN).reshape(n, 3, 3)  # [Σ w b]×
    t_ub = np.trace(BU, axis1=1, axis2=2)  # Σ t u·b
    w_bb = np.trace(bb, axis1=1, axis2=2)  # Σ w |b|²
    K = np.empty((n, 6, 6))
    K[:, :3, :3] = -uu
    K[:, :3, 3:] = -skew - um
    K[:, 3:, :3] = skew - np.transpose(um, (0, 2, 1))
    K[:, 3:, 3:] = -BU - bb - mm
    diag = np.arange(3)
    K[:, diag, diag] += sw[:, None]
    K[:, 3 + diag, 3 + diag] += (t_ub + w_bb)[:, None]
    return K


# [v]× = (v @ _SKEW_GEN).reshape(3, 3)
_SKEW_GEN = np.zeros((3, 9))
_SKEW_GEN[2, 1], _SKEW_GEN[1, 2] = -1.0, 1.0  # row 0: (0, −z, y)
_SKEW_GEN[2, 3], _SKEW_GEN[0, 5] = 1.0, -1.0  # row 1: (z, 0, −x)
_SKEW_GEN[1, 6], _SKEW_GEN[0, 7] = -1.0, 1.0  # row 2: (−y, x, 0)


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
