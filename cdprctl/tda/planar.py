"""The r = 2 polygon methods in one compiled call: feasible polygon, barycenter, minimum
2-norm or 1-norm point, SOTDA (vertices or a grid) and the tension rate limit.

One call instead of ~30 numpy operations and five kernel calls per cycle (87 → ~15 µs for
SOTDA on rowc, benchmarks/bench_loop.py).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from cdprctl.tda import polygon as pg
from cdprctl.tda.sotda import (
    displacements_kernel,
    grid_candidates_kernel,
    sotda_stiffness_kernel,
)

# method codes of the kernel
BARYCENTER, MIN_2NORM, MIN_1NORM, SOTDA = 0, 1, 2, 3
# slots of the kernel's ``info`` output
NV, AREA, BX, BY, SOTDA_DP, RATE_FLAG = range(6)


class PlanarWork(NamedTuple):
    """The polygon methods' workspace (passed as ``kernel_args``): the polygon's vertices
    (rows λ1, λ2; at most ``2 m + 8``), those of the rate-limited polygon, a scratch of the
    same shape, and ``info`` (the slots above)."""

    verts: np.ndarray
    verts_rate: np.ndarray
    tmp: np.ndarray
    info: np.ndarray

    @classmethod
    def of(cls, m: int) -> PlanarWork:
        n = 2 * m + 8
        return cls(np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2)), np.zeros(6))


@njit(cache=True)
def sotda_kernel(
    verts, nv, bx, by, N, t0, k, uT, W, rbT, free_len, dw, direction, nu
):  # pragma: no cover - compiled
    """Picard et al. 2020, Algorithm 1 with eq. (3)-(4) and (7): the vertex whose stiffness
    ``K(λ) = K0 + λ1 A1 + λ2 A2`` gives the smallest ``|d · δp|`` for ``δX = K⁻¹ δw`` (a
    singular ``K`` is never chosen), then the intermediate point ``λ_b + ν (λ_s − λ_b)``
    (Fig. 2). Returns ``(x, y, d · δp at that point)``."""
    S = np.empty((3, 6, 6))
    sotda_stiffness_kernel(N, t0, k, uT, W, rbT, free_len, S)
    K0 = S[0]
    dX = np.empty((nv, 6))
    displacements_kernel(K0, S[1], S[2], verts, nv, dw, dX)
    best = 0
    best_dp = math.inf
    for j in range(nv):
        dp = abs(dX[j, 0] * direction[0] + dX[j, 1] * direction[1] + dX[j, 2] * direction[2])
        if dp < best_dp:  # False for NaN: a singular K(λ)
            best, best_dp = j, dp
    x = bx + nu * (verts[best, 0] - bx)
    y = by + nu * (verts[best, 1] - by)
    lam = np.empty((1, 2))
    lam[0, 0], lam[0, 1] = x, y
    d1 = np.empty((1, 6))
    displacements_kernel(K0, S[1], S[2], lam, 1, dw, d1)
    return x, y, d1[0, 0] * direction[0] + d1[0, 1] * direction[1] + d1[0, 2] * direction[2]


@njit(cache=True)
def rate_limit_kernel(x, y, N, t0, lo, hi, t_prev, step, verts, tmp):  # pragma: no cover
    """Nearest point to ``(x, y)`` whose tensions stay within ``step`` (N) of ``t_prev``: the
    polygon with bounds tightened around ``t_prev``. Returns ``(x, y, flag)``: flag 0 when
    already within, 1 when moved, 2 when the wrench cannot be met within the rate (unchanged:
    equilibrium first)."""
    m = N.shape[0]
    lo2 = np.empty(m)
    hi2 = np.empty(m)
    inside = True
    ordered = True
    for i in range(m):
        lo2[i] = max(lo[i], t_prev[i] - step)
        hi2[i] = min(hi[i], t_prev[i] + step)
        ordered = ordered and lo2[i] <= hi2[i]
        t = t0[i] + N[i, 0] * x + N[i, 1] * y
        if not (lo2[i] - 1e-9 <= t <= hi2[i] + 1e-9):
            inside = False
    if inside:
        return x, y, 0
    nv = pg.polygon_kernel(N, t0, lo2, hi2, 1e-9, verts, tmp) if ordered else 0
    if nv == 0:
        return x, y, 2
    x2, y2 = pg.min_quadratic_kernel(verts, nv, 1.0, 0.0, 1.0, -x, -y)
    return x2, y2, 1


@njit(cache=True)
def planar_kernel(
    method, N, t0, lo, hi, k, kin, dw, direction, nu, grid, t_prev, step, work, lam, tensions
):  # pragma: no cover - compiled
    """The polygon of ``t0 + N λ`` within ``[lo, hi]`` into ``work.verts``, the method's point
    (``method``: BARYCENTER, MIN_2NORM, MIN_1NORM or SOTDA — its candidates the vertices, or
    with ``grid`` > 0 a ``grid × grid`` mesh over the polygon too; SOTDA reads the stiffness
    ``k`` (N/m) and the kinematics ``kin``, a ``KinArrays``), rate-limited around ``t_prev``
    when ``step`` (N) is finite; ``lam`` and ``tensions`` (N) out, and ``work.info`` (see the
    slots above). False when the polygon is empty (nothing else written but ``info[NV]``)."""
    verts, verts_rate, tmp, info = work
    nv = pg.polygon_kernel(N, t0, lo, hi, 1e-9, verts, tmp)
    info[NV] = nv
    if nv == 0:
        return False
    area, bx, by = pg.area_centroid_kernel(verts, nv)
    info[AREA], info[BX], info[BY] = area, bx, by
    info[SOTDA_DP] = math.nan
    if method == BARYCENTER:
        x, y = bx, by
    elif method == MIN_2NORM:
        # ‖t‖² = ‖t0‖² + ‖λ‖² (orthonormal N, t0 ⊥ null(W)): the point nearest λ = 0
        x, y = pg.min_quadratic_kernel(verts, nv, 1.0, 0.0, 1.0, 0.0, 0.0)
    elif method == MIN_1NORM:
        c0 = c1 = 0.0  # Σ t_i = Σ t0_i + (1ᵀN) λ, tensions being positive
        for i in range(N.shape[0]):
            c0 += N[i, 0]
            c1 += N[i, 1]
        j = 0
        for v in range(1, nv):
            if verts[v, 0] * c0 + verts[v, 1] * c1 < verts[j, 0] * c0 + verts[j, 1] * c1:
                j = v
        x, y = verts[j, 0], verts[j, 1]
    else:
        cand, nc = verts, nv
        if grid > 0:  # the paper's meshgrid search
            cand = np.empty((grid * grid + nv, 2))
            nc = grid_candidates_kernel(verts, nv, grid, cand)
        W, rbT, free_len = kin[10], kin[4], kin[7]  # KinArrays' fields, by position
        x, y, info[SOTDA_DP] = sotda_kernel(
            cand, nc, bx, by, N, t0, k, W[:3], W, rbT, free_len, dw, direction, nu
        )
    info[RATE_FLAG] = 0.0
    if math.isfinite(step):
        x, y, flag = rate_limit_kernel(x, y, N, t0, lo, hi, t_prev, step, verts_rate, tmp)
        info[RATE_FLAG] = flag
    lam[0], lam[1] = x, y
    for i in range(N.shape[0]):
        tensions[i] = t0[i] + N[i, 0] * x + N[i, 1] * y
    return True


@njit(cache=True)
def feasible_scale_kernel(N, t_ff, t_fb, lo, hi, verts, tmp, t0):  # pragma: no cover - compiled
    """The largest ``s`` in [0, 1] for which ``t_ff + s t_fb + N λ`` lies inside ``[lo, hi]``
    for some ``λ`` (r = 2: the feasible polygon is not empty), by bisection to 1e-6; −1 when
    even ``s = 0`` is infeasible. The set of such ``s`` is an interval (a convex set's
    section), so bisection finds its end. ``t0`` (m,) scratch."""
    m = N.shape[0]
    for i in range(m):
        t0[i] = t_ff[i] + t_fb[i]
    if pg.polygon_kernel(N, t0, lo, hi, 1e-9, verts, tmp) > 0:
        return 1.0
    for i in range(m):
        t0[i] = t_ff[i]
    if pg.polygon_kernel(N, t0, lo, hi, 1e-9, verts, tmp) == 0:
        return -1.0
    a, b = 0.0, 1.0  # feasible at a, not at b
    while b - a > 1e-6:
        s = 0.5 * (a + b)
        for i in range(m):
            t0[i] = t_ff[i] + s * t_fb[i]
        if pg.polygon_kernel(N, t0, lo, hi, 1e-9, verts, tmp) > 0:
            a = s
        else:
            b = s
    return a
