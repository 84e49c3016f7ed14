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

from cdprctl.core.numerics import cycle_kernel
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.kinematics import KinematicsData
from cdprctl.geometry.stiffness import _ka_weighted
from cdprctl.tda.polygon import Point


@cycle_kernel
def sotda_stiffness_kernel(N, t0, k, uT, W, rbT, free_len, T, S):  # pragma: no cover - compiled
    """``S`` (3, 6, 6) ← ``K0 = Kp + Ka(t0)``, ``A1 = Ka(N_1)``, ``A2 = Ka(N_2)`` (Picard et
    al. 2020, eq. (3)-(4): ``K(λ) = K0 + λ1 A1 + λ2 A2``), ``Kp = W diag(k) Wᵀ``; ``T``
    (3, m) scratch."""
    m = N.shape[0]
    for i in range(m):
        T[0, i] = t0[i]
        T[1, i] = N[i, 0]
        T[2, i] = N[i, 1]
    _ka_weighted(uT, W, rbT, free_len, T, S)
    for r in range(6):
        for c in range(6):
            s = 0.0
            for i in range(m):
                s += W[r, i] * k[i] * W[c, i]
            S[0, r, c] += s


class SotdaModel:
    """``K(λ) = K0 + λ1 A1 + λ2 A2`` at one pose (``sotda_stiffness_kernel``)."""

    def __init__(self, data: KinematicsData, k: FloatArray, t0: FloatArray, N: FloatArray):
        S = np.empty((3, 6, 6))
        sotda_stiffness_kernel(
            np.ascontiguousarray(N, dtype=float),
            np.ascontiguousarray(t0, dtype=float),
            np.ascontiguousarray(k, dtype=float),
            data.uT,
            data.W,
            data.rbT,
            data.free_length,
            np.empty((3, len(t0))),
            S,
        )
        self.K0, self.A1, self.A2 = S[0], S[1], S[2]

    def displacements(self, lam: FloatArray, delta_wrench: FloatArray) -> FloatArray:
        """Displacement screws ``δX = K(λ)⁻¹ δw`` (m, rad) for candidates ``lam`` (n, 2);
        NaN rows where ``K(λ)`` is singular."""
        out = np.empty((len(lam), 6))
        displacements_kernel(
            self.K0,
            self.A1,
            self.A2,
            np.ascontiguousarray(lam),
            len(lam),
            delta_wrench,
            out,
            np.empty((6, 7)),
        )
        return out


@cycle_kernel
def displacements_kernel(K0, A1, A2, lam, n, dw, out, K):  # pragma: no cover - compiled
    """``out[j] = (K0 + λ_j1 A1 + λ_j2 A2)⁻¹ dw`` by Gaussian elimination with partial
    pivoting; NaN where singular. ``K`` (6, 7) scratch."""
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
            for r in range(6):
                out[j, r] = np.nan
            continue
        for r in range(5, -1, -1):
            s = K[r, 6]
            for k in range(r + 1, 6):
                s -= K[r, k] * out[j, k]
            out[j, r] = s / K[r, r]


def grid_candidates(poly: Sequence[Point] | FloatArray, n: int) -> FloatArray:
    """Points of an ``n × n`` grid over the polygon's bounding box that lie inside it, plus its
    vertices (the paper's meshgrid search of the feasible polygon)."""
    P = np.ascontiguousarray(np.array(poly, dtype=float).reshape(-1, 2))
    out = np.empty((n * n + len(P), 2))
    return out[: grid_candidates_kernel(P, len(P), n, out)]


@cycle_kernel
def grid_candidates_kernel(verts, nv, n, out):  # pragma: no cover - compiled
    """:func:`grid_candidates` of the counter-clockwise polygon ``verts[:nv]`` into ``out``
    (room for ``n² + nv`` rows); returns the number of rows written. The grid is numpy's
    ``linspace`` per axis, x fastest; inside means left of every edge within 1e-12."""
    lo_x = hi_x = verts[0, 0]
    lo_y = hi_y = verts[0, 1]
    for k in range(1, nv):
        lo_x, hi_x = min(lo_x, verts[k, 0]), max(hi_x, verts[k, 0])
        lo_y, hi_y = min(lo_y, verts[k, 1]), max(hi_y, verts[k, 1])
    step_x = (hi_x - lo_x) / (n - 1) if n > 1 else 0.0
    step_y = (hi_y - lo_y) / (n - 1) if n > 1 else 0.0
    count = 0
    for i in range(n):
        y = hi_y if i == n - 1 and n > 1 else i * step_y + lo_y
        for j in range(n):
            x = hi_x if j == n - 1 and n > 1 else j * step_x + lo_x
            inside = True
            for k in range(nv):
                px, py = verts[k, 0], verts[k, 1]
                qx, qy = verts[(k + 1) % nv, 0], verts[(k + 1) % nv, 1]
                ex, ey = qx - px, qy - py
                scale = max(abs(ex) + abs(ey), 1e-300)
                if (ex * (y - py) - ey * (x - px)) / scale < -1e-12:
                    inside = False
                    break
            if inside:
                out[count, 0], out[count, 1] = x, y
                count += 1
    for k in range(nv):
        out[count, 0], out[count, 1] = verts[k, 0], verts[k, 1]
        count += 1
    return count
