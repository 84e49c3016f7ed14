"""Stiffness Oriented TDA (Picard et al. 2020, §3, Algorithm 1 and eq. (7)).

For tensions ``t(λ) = t0 + N λ`` the stiffness is ``K(λ) = Kp + Ka(t(λ))`` (eq. (3)-(4)), and
``Ka`` is linear in the tensions: ``K(λ) = K0 + λ1 A1 + λ2 A2`` with ``K0 = Kp + Ka(t0)`` and
``A_j = Ka(N_j)``. The candidate minimising ``|d · δp|`` with ``δX = K⁻¹ δw_e`` (eq. (7)) is
selected among the polygon's vertices (the paper's real-time variant: at least one cable at
``t_max`` and a second at a bound) or over a grid covering the polygon (the paper's meshgrid).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from cdprctl.kinematics import KinematicsData
from cdprctl.rotation import FloatArray
from cdprctl.stiffness import active_stiffness_weighted
from cdprctl.tda.polygon import Point


class SotdaModel:
    """``K(λ) = K0 + λ1 A1 + λ2 A2`` at one pose (Picard et al. 2020, eq. (3)-(4))."""

    def __init__(self, data: KinematicsData, k: FloatArray, t0: FloatArray, N: FloatArray):
        T = np.empty((3, data.n_cables))
        T[0] = t0
        T[1:] = N.T
        S = active_stiffness_weighted(data, T)
        Kp = (data.W * k) @ data.WT
        self.K0 = Kp + S[0]
        self.A1 = S[1]
        self.A2 = S[2]

    def displacements(self, lam: FloatArray, delta_wrench: FloatArray) -> FloatArray:
        """Displacement screws ``δX = K(λ)⁻¹ δw`` (m, rad) for candidates ``lam`` (n, 2);
        NaN rows where ``K(λ)`` is singular."""
        out = np.empty((len(lam), 6))
        displacements_kernel(
            self.K0, self.A1, self.A2, np.ascontiguousarray(lam), len(lam), delta_wrench, out
        )
        return out


def sotda_point(
    model: SotdaModel,
    candidates: FloatArray,
    delta_wrench: FloatArray,
    direction: FloatArray,
) -> tuple[int, FloatArray]:
    """Index of the candidate with the smallest ``|direction · δp|`` and all those values (m).

    Candidates whose stiffness matrix is singular (an unstable equilibrium, signalled by a
    non-finite displacement) are never selected.
    """
    dX = model.displacements(candidates, delta_wrench)
    dp = np.abs(dX[:, :3] @ direction)
    dp = np.where(np.isfinite(dp), dp, np.inf)
    return int(np.argmin(dp)), dp


@njit(cache=True)
def displacements_kernel(K0, A1, A2, lam, n, dw, out):  # pragma: no cover - compiled
    """``out[j] = (K0 + λ_j1 A1 + λ_j2 A2)⁻¹ dw`` by Gaussian elimination with partial
    pivoting; NaN where singular."""
    K = np.empty((6, 7))
    for j in range(n):
        l1, l2 = lam[j, 0], lam[j, 1]
        for r in range(6):
            for c in range(6):
                K[r, c] = K0[r, c] + l1 * A1[r, c] + l2 * A2[r, c]
            K[r, 6] = dw[r]
        singular = False
        for c in range(6):
            piv = c
            for r in range(c + 1, 6):
                if abs(K[r, c]) > abs(K[piv, c]):
                    piv = r
            if not abs(K[piv, c]) > 1e-300:
                singular = True
                break
            if piv != c:
                for k in range(c, 7):
                    K[c, k], K[piv, k] = K[piv, k], K[c, k]
            for r in range(c + 1, 6):
                f = K[r, c] / K[c, c]
                for k in range(c, 7):
                    K[r, k] -= f * K[c, k]
        if singular:
            out[j, :] = np.nan
            continue
        for r in range(5, -1, -1):
            s = K[r, 6]
            for k in range(r + 1, 6):
                s -= K[r, k] * out[j, k]
            out[j, r] = s / K[r, r]


def grid_candidates(poly: Sequence[Point] | FloatArray, n: int) -> FloatArray:
    """Points of an ``n × n`` grid over the polygon's bounding box that lie inside it, plus its
    vertices (the paper's meshgrid search of the feasible polygon)."""
    P = np.array(poly)
    lo, hi = P.min(axis=0), P.max(axis=0)
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    inside = np.ones(len(pts), dtype=bool)
    Q = np.roll(P, -1, axis=0)
    for (px, py), (qx, qy) in zip(P, Q, strict=True):  # CCW: inside is left of each edge
        ex, ey = qx - px, qy - py
        scale = max(abs(ex) + abs(ey), 1e-300)
        inside &= (ex * (pts[:, 1] - py) - ey * (pts[:, 0] - px)) / scale >= -1e-12
    return np.concatenate([pts[inside], P], axis=0)
