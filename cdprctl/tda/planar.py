"""The r = 2 polygon methods in one compiled call: feasible polygon, barycenter, minimum
2-norm or 1-norm point, SOTDA (vertices or a grid) and the tension rate limit.

One call instead of ~30 numpy operations and five kernel calls per cycle (87 → ~15 µs for
SOTDA on rowc, benchmarks/bench_loop.py).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cdprctl.core.numerics import cycle_kernel
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
    """The polygon methods' workspace (passed as ``kernel_args``; the kernel takes no block):
    the polygon's vertices (rows λ1, λ2; at most ``2 m + 8``), those of the rate-limited
    polygon, a scratch of the same shape, ``info`` (the slots above); the polygon's strips
    ``bounds`` (3, m) and the rate limit's tightened ones ``rate_bounds`` (2, m); SOTDA's
    ``S`` (3, 6, 6) = K0, A1, A2, its tensions ``T`` (3, m), the elimination's ``K`` (6, 7),
    the candidates ``cand`` (rows λ1, λ2: the vertices, or a ``grid × grid`` mesh and the
    vertices) and their displacements ``dX`` (a row each; the last for the chosen point)."""

    verts: np.ndarray
    verts_rate: np.ndarray
    tmp: np.ndarray
    info: np.ndarray
    bounds: np.ndarray
    rate_bounds: np.ndarray
    S: np.ndarray
    T: np.ndarray
    K: np.ndarray
    cand: np.ndarray
    dX: np.ndarray

    @classmethod
    def of(cls, m: int, grid: int = 0) -> PlanarWork:
        """For ``m`` cables and SOTDA's ``grid`` (points per axis; 0: the vertices only)."""
        n = 2 * m + 8
        rows = grid * grid + n
        return cls(np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2)), np.zeros(6),
                   np.zeros((3, m)), np.zeros((2, m)), np.zeros((3, 6, 6)), np.zeros((3, m)),
                   np.zeros((6, 7)), np.zeros((rows, 2)), np.zeros((rows + 1, 6)))  # fmt: skip


@cycle_kernel
def sotda_kernel(
    verts, nv, bx, by, N, t0, k, uT, W, rbT, free_len, dw, direction, nu, S, T, K, dX, lam
):  # pragma: no cover - compiled
    """Picard et al. 2020, Algorithm 1 with eq. (3)-(4) and (7): the vertex whose stiffness
    ``K(λ) = K0 + λ1 A1 + λ2 A2`` gives the smallest ``|d · δp|`` for ``δX = K⁻¹ δw`` (a
    singular ``K`` is never chosen), then the intermediate point ``λ_b + ν (λ_s − λ_b)``
    (Fig. 2). Returns ``(x, y, d · δp at that point)``. Scratch (``PlanarWork``): ``S``,
    ``T``, ``K``, ``dX`` (``nv + 1`` rows at least), ``lam`` (1, 2)."""
    sotda_stiffness_kernel(N, t0, k, uT, W, rbT, free_len, T, S)
    K0 = S[0]
    displacements_kernel(K0, S[1], S[2], verts, nv, dw, dX, K)
    best = 0
    best_dp = math.inf
    for j in range(nv):
        dp = abs(dX[j, 0] * direction[0] + dX[j, 1] * direction[1] + dX[j, 2] * direction[2])
        if dp < best_dp:  # False for NaN: a singular K(λ)
            best, best_dp = j, dp
    x = bx + nu * (verts[best, 0] - bx)
    y = by + nu * (verts[best, 1] - by)
    lam[0, 0], lam[0, 1] = x, y
    d1 = dX[nv : nv + 1]
    displacements_kernel(K0, S[1], S[2], lam, 1, dw, d1, K)
    return x, y, d1[0, 0] * direction[0] + d1[0, 1] * direction[1] + d1[0, 2] * direction[2]


@cycle_kernel
def rate_limit_kernel(
    x, y, N, t0, lo, hi, t_prev, step, verts, tmp, bounds, rate_bounds
):  # pragma: no cover - compiled
    """Nearest point to ``(x, y)`` whose tensions stay within ``step`` (N) of ``t_prev``: the
    polygon with bounds tightened around ``t_prev``. Returns ``(x, y, flag)``: flag 0 when
    already within, 1 when moved, 2 when the wrench cannot be met within the rate (unchanged:
    equilibrium first). Scratch: ``bounds`` (3, m), ``rate_bounds`` (2, m)."""
    m = N.shape[0]
    lo2, hi2 = rate_bounds[0], rate_bounds[1]
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
    nv = pg.polygon_into(N, t0, lo2, hi2, 1e-9, verts, tmp, bounds) if ordered else 0
    if nv == 0:
        return x, y, 2
    x2, y2 = pg.min_quadratic_kernel(verts, nv, 1.0, 0.0, 1.0, -x, -y)
    return x2, y2, 1


@cycle_kernel
def planar_kernel(
    method, N, t0, lo, hi, k, kin, dw, direction, nu, grid, t_prev, step, work, lam, tensions
):  # pragma: no cover - compiled
    """The polygon of ``t0 + N λ`` within ``[lo, hi]`` into ``work.verts``, the method's point
    (``method``: BARYCENTER, MIN_2NORM, MIN_1NORM or SOTDA — its candidates the vertices, or
    with ``grid`` > 0 a ``grid × grid`` mesh over the polygon too; SOTDA reads the stiffness
    ``k`` (N/m) and the kinematics ``kin``, a ``KinArrays``), rate-limited around ``t_prev``
    when ``step`` (N) is finite; ``lam`` and ``tensions`` (N) out, and ``work.info`` (see the
    slots above). False when the polygon is empty (nothing else written but ``info[NV]``).
    Takes no block: its scratch is ``work``'s (a ``grid`` beyond the one it was sized for
    falls back to the vertices)."""
    verts, verts_rate, tmp, info, bounds, rate_bounds, S, T, K, cand_grid, dX = work
    nv = pg.polygon_into(N, t0, lo, hi, 1e-9, verts, tmp, bounds)
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
        if grid > 0 and grid * grid + nv <= cand_grid.shape[0] - 1:  # the paper's meshgrid
            cand = cand_grid
            nc = grid_candidates_kernel(verts, nv, grid, cand)
        W, rbT, free_len = kin[10], kin[4], kin[7]  # KinArrays' fields, by position
        x, y, info[SOTDA_DP] = sotda_kernel(
            cand,
            nc,
            bx,
            by,
            N,
            t0,
            k,
            W[:3],
            W,
            rbT,
            free_len,
            dw,
            direction,
            nu,
            S,
            T,
            K,
            dX,
            tmp[:1],  # the polygon's clipping scratch, free by now
        )
    info[RATE_FLAG] = 0.0
    if math.isfinite(step):
        x, y, flag = rate_limit_kernel(
            x, y, N, t0, lo, hi, t_prev, step, verts_rate, tmp, bounds, rate_bounds
        )
        info[RATE_FLAG] = flag
    lam[0], lam[1] = x, y
    for i in range(N.shape[0]):
        tensions[i] = t0[i] + N[i, 0] * x + N[i, 1] * y
    return True


@cycle_kernel
def feasible_scale_kernel(
    N, t_ff, t_fb, lo, hi, verts, tmp, t0, bounds
):  # pragma: no cover - compiled
    """The largest ``s`` in [0, 1] for which ``t_ff + s t_fb + N λ`` lies inside ``[lo, hi]``
    for some ``λ`` (r = 2: the feasible polygon is not empty), by bisection to 1e-6; −1 when
    even ``s = 0`` is infeasible. The set of such ``s`` is an interval (a convex set's
    section), so bisection finds its end. ``t0`` (m,) and ``bounds`` (3, m) scratch."""
    m = N.shape[0]
    for i in range(m):
        t0[i] = t_ff[i] + t_fb[i]
    if pg.polygon_into(N, t0, lo, hi, 1e-9, verts, tmp, bounds) > 0:
        return 1.0
    for i in range(m):
        t0[i] = t_ff[i]
    if pg.polygon_into(N, t0, lo, hi, 1e-9, verts, tmp, bounds) == 0:
        return -1.0
    a, b = 0.0, 1.0  # feasible at a, not at b
    while b - a > 1e-6:
        s = 0.5 * (a + b)
        for i in range(m):
            t0[i] = t_ff[i] + s * t_fb[i]
        if pg.polygon_into(N, t0, lo, hi, 1e-9, verts, tmp, bounds) > 0:
            a = s
        else:
            b = s
    return a
