"""The feasible polygon of a redundancy-2 robot and 2-D optimisation over it.

Picard et al. 2020, eq. (6): ``{λ ∈ R² | t_min <= t0 + N λ <= t_max}``, a convex polygon, the
intersection of m strips (one per cable). It is built by clipping the parallelogram of two
strips with the others (Sutherland-Hodgman, both sides of a strip in one pass), in compiled
kernels: at this size (8 strips, polygons of 4-8 vertices) numpy's per-call overhead would cost
more than the arithmetic, and plain Python floats ~40 µs.

Vertices are ``(x, y)`` tuples in counter-clockwise order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from cdprctl.core.numerics import cycle_kernel
from cdprctl.core.rotation import FloatArray

Point = tuple[float, float]


def feasible_polygon(
    N: FloatArray,
    t0: FloatArray,
    t_lo: FloatArray,
    t_hi: FloatArray,
    eps: float = 1e-9,
) -> list[Point]:
    """Vertices (counter-clockwise) of ``{λ | t_lo <= t0 + N λ <= t_hi}``; ``[]`` when empty.

    ``N`` (m×2) must have independent columns (any basis: orthonormality is not assumed).
    ``eps`` (N) tolerates round-off on the bounds. The clipping starts from the parallelogram
    of the two most nearly perpendicular strips and clips it with the others.
    """
    m = N.shape[0]
    verts = np.empty((2 * m + 8, 2))
    nv = polygon_kernel(np.ascontiguousarray(N), t0, t_lo, t_hi, eps, verts, np.empty_like(verts))
    return [(float(x), float(y)) for x, y in verts[:nv]]


def _as_array(poly: Sequence[Point] | FloatArray) -> FloatArray:
    return np.ascontiguousarray(np.asarray(poly, dtype=np.float64).reshape(-1, 2))


def area_centroid(poly: Sequence[Point] | FloatArray) -> tuple[float, Point]:
    """Area and area centroid of a polygon, closing edge included (shoelace formula).

    A degenerate polygon (a segment or a point, area ~ 0) returns the mean of its vertices.
    """
    P = _as_array(poly)
    if len(P) == 0:
        return 0.0, (math.nan, math.nan)
    a, cx, cy = area_centroid_kernel(P, len(P))
    return float(a), (float(cx), float(cy))


def contains(poly: Sequence[Point] | FloatArray, x: float, y: float, tol: float = 1e-9) -> bool:
    """True when ``(x, y)`` is inside the counter-clockwise convex polygon (within ``tol``)."""
    P = _as_array(poly)
    return bool(contains_kernel(P, len(P), x, y, tol))


def min_quadratic(
    poly: Sequence[Point] | FloatArray, h11: float, h12: float, h22: float, g1: float, g2: float
) -> Point:
    """Minimiser over the convex polygon of ``½ λᵀ H λ + gᵀ λ`` (``H`` symmetric positive
    definite). Interior minimum if inside, else the best point of the edges (the function is
    convex, so its constrained minimum lies on the boundary)."""
    P = _as_array(poly)
    x, y = min_quadratic_kernel(P, len(P), h11, h12, h22, g1, g2)
    return float(x), float(y)


# -- compiled kernels (arrays in, arrays out; ``nv`` = the number of valid vertices) ------------


@njit(cache=True)
def polygon_kernel(N, t0, t_lo, t_hi, eps, verts, tmp):  # pragma: no cover - compiled
    """Clip the parallelogram of two strips with the other strips; vertices into ``verts``
    (counter-clockwise); returns their number (0: empty). ``polygon_into`` on a new scratch."""
    return polygon_into(N, t0, t_lo, t_hi, eps, verts, tmp, np.empty((3, N.shape[0])))


@cycle_kernel
def polygon_into(N, t0, t_lo, t_hi, eps, verts, tmp, bounds):  # pragma: no cover - compiled
    """``polygon_kernel`` with its scratch given: ``bounds`` (3, m) (no block taken)."""
    m = N.shape[0]
    lo, hi, norms = bounds[0], bounds[1], bounds[2]
    for i in range(m):
        lo[i] = t_lo[i] - t0[i] - eps
        hi[i] = t_hi[i] - t0[i] + eps
        norms[i] = math.sqrt(N[i, 0] * N[i, 0] + N[i, 1] * N[i, 1])
    i0 = 0
    for i in range(m):
        if norms[i] > norms[i0]:
            i0 = i
    best = -1.0
    i1 = -1
    for j in range(m):
        if j != i0 and norms[j] > 0.0:
            sn = abs(N[i0, 0] * N[j, 1] - N[i0, 1] * N[j, 0]) / (norms[i0] * norms[j])
            if sn > best:
                best = sn
                i1 = j
    if best < 1e-12 or lo[i0] > hi[i0] or lo[i1] > hi[i1]:
        return 0
    # parallelogram: corners (s_a, s_b) in (lo, lo), (hi, lo), (hi, hi), (lo, hi)
    ax, ay, bx, by = N[i0, 0], N[i0, 1], N[i1, 0], N[i1, 1]
    det = ax * by - ay * bx
    sa = (lo[i0], hi[i0], hi[i0], lo[i0])
    sb = (lo[i1], lo[i1], hi[i1], hi[i1])
    for k in range(4):
        kk = k if det > 0.0 else 3 - k  # counter-clockwise either way
        verts[k, 0] = (sa[kk] * by - sb[kk] * ay) / det
        verts[k, 1] = (ax * sb[kk] - bx * sa[kk]) / det
    nv = 4
    for i in range(m):
        if i == i0 or i == i1:  # noqa: SIM109 - plain comparisons in the kernel
            continue
        if norms[i] == 0.0:  # a cable the redundancy cannot change: in bounds or not at all
            if not (lo[i] <= 0.0 <= hi[i]):
                return 0
            continue
        nv = _clip_strip(verts, nv, N[i, 0], N[i, 1], lo[i], hi[i], tmp)
        if nv == 0:
            return 0
        for k in range(nv):
            verts[k, 0] = tmp[k, 0]
            verts[k, 1] = tmp[k, 1]
    return _dedupe(verts, nv)


@cycle_kernel
def _clip_strip(verts, nv, ax, ay, lo, hi, out):  # pragma: no cover - compiled
    """Sutherland-Hodgman with both sides of ``lo <= ax·x + ay·y <= hi`` in one pass; the
    result goes to ``out`` (always, even when nothing is cut); returns its vertex count."""
    smin = math.inf
    smax = -math.inf
    for k in range(nv):
        s = ax * verts[k, 0] + ay * verts[k, 1]
        smin = min(smin, s)
        smax = max(smax, s)
    if smin >= lo and smax <= hi:
        for k in range(nv):
            out[k, 0] = verts[k, 0]
            out[k, 1] = verts[k, 1]
        return nv
    n_out = 0
    px, py = verts[nv - 1, 0], verts[nv - 1, 1]
    sp = ax * px + ay * py
    for k in range(nv):
        qx, qy = verts[k, 0], verts[k, 1]
        sq = ax * qx + ay * qy
        ds = sq - sp
        if ds == 0.0:
            if lo <= sp <= hi:
                out[n_out, 0], out[n_out, 1] = qx, qy
                n_out += 1
        else:
            ua, ub = (lo - sp) / ds, (hi - sp) / ds
            if ua > ub:
                ua, ub = ub, ua
            u0 = ua if ua > 0.0 else 0.0
            u1 = ub if ub < 1.0 else 1.0
            if u0 <= u1:
                if u0 > 0.0:  # entering: the crossing point
                    out[n_out, 0] = px + u0 * (qx - px)
                    out[n_out, 1] = py + u0 * (qy - py)
                    n_out += 1
                if u1 < 1.0:  # leaving before Q
                    out[n_out, 0] = px + u1 * (qx - px)
                    out[n_out, 1] = py + u1 * (qy - py)
                else:
                    out[n_out, 0], out[n_out, 1] = qx, qy
                n_out += 1
        px, py, sp = qx, qy, sq
    return n_out


@cycle_kernel
def _dedupe(verts, nv):  # pragma: no cover - compiled
    """Drop vertices repeating the previous one (clipping through a vertex makes them)."""
    if nv < 2:
        return nv
    scale = 1.0
    for k in range(nv):
        scale = max(scale, abs(verts[k, 0]), abs(verts[k, 1]))
    tol = 1e-12 * scale
    n = 1
    for k in range(1, nv):
        if abs(verts[k, 0] - verts[n - 1, 0]) > tol or abs(verts[k, 1] - verts[n - 1, 1]) > tol:
            verts[n, 0], verts[n, 1] = verts[k, 0], verts[k, 1]
            n += 1
    if (
        n > 1
        and abs(verts[n - 1, 0] - verts[0, 0]) <= tol
        and abs(verts[n - 1, 1] - verts[0, 1]) <= tol
    ):
        n -= 1
    return n


@cycle_kernel
def area_centroid_kernel(verts, nv):  # pragma: no cover - compiled
    """(area, cx, cy): shoelace formula, closing edge included, shifted to the first vertex
    for less cancellation; the vertex mean for a degenerate polygon."""
    x0, y0 = verts[0, 0], verts[0, 1]
    a2 = cx = cy = 0.0
    px, py = 0.0, 0.0
    scale = 1e-300
    for k in range(1, nv + 1):
        j = k % nv
        qx, qy = verts[j, 0] - x0, verts[j, 1] - y0
        cross = px * qy - qx * py
        a2 += cross
        cx += (px + qx) * cross
        cy += (py + qy) * cross
        px, py = qx, qy
        scale = max(scale, abs(qx) + abs(qy))
    if abs(a2) <= 1e-12 * scale * scale:
        mx = my = 0.0
        for k in range(nv):
            mx += verts[k, 0]
            my += verts[k, 1]
        return 0.0, mx / nv, my / nv
    return 0.5 * abs(a2), x0 + cx / (3.0 * a2), y0 + cy / (3.0 * a2)


@cycle_kernel
def contains_kernel(verts, nv, x, y, tol):  # pragma: no cover - compiled
    if nv == 0:
        return False
    if nv == 1:
        return abs(verts[0, 0] - x) <= tol and abs(verts[0, 1] - y) <= tol
    px, py = verts[nv - 1, 0], verts[nv - 1, 1]
    for k in range(nv):
        qx, qy = verts[k, 0], verts[k, 1]
        ex, ey = qx - px, qy - py
        norm = math.sqrt(ex * ex + ey * ey)
        if norm > 0.0 and (ex * (y - py) - ey * (x - px)) / norm < -tol:
            return False
        px, py = qx, qy
    return True


@cycle_kernel
def min_quadratic_kernel(verts, nv, h11, h12, h22, g1, g2):  # pragma: no cover - compiled
    det = h11 * h22 - h12 * h12
    ux = -(h22 * g1 - h12 * g2) / det
    uy = -(-h12 * g1 + h11 * g2) / det
    if contains_kernel(verts, nv, ux, uy, 0.0):
        return ux, uy
    if nv == 1:
        return verts[0, 0], verts[0, 1]
    bx, by = verts[0, 0], verts[0, 1]
    best = math.inf
    px, py = verts[nv - 1, 0], verts[nv - 1, 1]
    for k in range(nv):
        qx, qy = verts[k, 0], verts[k, 1]
        dx, dy = qx - px, qy - py
        curv = dx * (h11 * dx + h12 * dy) + dy * (h12 * dx + h22 * dy)
        # gradient at P along d: dᵀ(H P + g)
        slope = dx * (h11 * px + h12 * py + g1) + dy * (h12 * px + h22 * py + g2)
        s = 0.0 if curv <= 0.0 else min(1.0, max(0.0, -slope / curv))
        x, y = px + s * dx, py + s * dy
        f = 0.5 * (h11 * x * x + 2.0 * h12 * x * y + h22 * y * y) + g1 * x + g2 * y
        if f < best:
            best, bx, by = f, x, y
        px, py = qx, qy
    return bx, by


def least_violating(
    N: FloatArray, t0: FloatArray, t_lo: FloatArray, t_hi: FloatArray
) -> tuple[FloatArray, float]:
    """``λ`` minimising the largest bound violation ``max_i max(lo_i − t_i, t_i − hi_i)``.

    For an infeasible wrench (empty polygon), and, negated, the tension margin of a feasible
    one (``cdprctl.tda.workspace``). Returns ``(λ, s)`` with ``s`` (N) the largest violation
    there (:func:`least_violating_kernel`).
    """
    lx, ly, s = least_violating_kernel(np.ascontiguousarray(N), t0, t_lo, t_hi)
    return np.array([lx, ly]), float(s)


@njit(cache=True)
def least_violating_kernel(N, t0, lo, hi):  # pragma: no cover - compiled
    """``(λx, λy, s)``: the minimum over λ of ``s(λ) = max_k g_k(λ)``, the 2m affine functions
    ``lo_i − t0_i − N_i λ`` and ``t0_i + N_i λ − hi_i``. A 2-D linear programme: its minimum
    is where three of them are equal (a vertex of the epigraph), so every triple is solved by
    Cramer's rule and the best kept; a triple is dropped as soon as one function exceeds the
    best so far. ``s = inf`` when every triple is singular (``N`` of rank < 2)."""
    m = N.shape[0]
    n = 2 * m
    ga = np.empty(n)
    gb = np.empty(n)
    gc = np.empty(n)
    for i in range(m):
        ga[i], gb[i], gc[i] = -N[i, 0], -N[i, 1], lo[i] - t0[i]
        ga[m + i], gb[m + i], gc[m + i] = N[i, 0], N[i, 1], t0[i] - hi[i]
    scale = 0.0
    for k in range(n):
        scale = max(scale, abs(ga[k]), abs(gb[k]))
    best, bx, by = math.inf, 0.0, 0.0
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                # a λx + b λy − s = −c on rows i, j, k; subtracting row i leaves 2×2 in λ
                a1, b1, c1 = ga[j] - ga[i], gb[j] - gb[i], gc[i] - gc[j]
                a2, b2, c2 = ga[k] - ga[i], gb[k] - gb[i], gc[i] - gc[k]
                det = a1 * b2 - a2 * b1
                if abs(det) <= 1e-12 * scale * scale:
                    continue
                x = (c1 * b2 - c2 * b1) / det
                y = (a1 * c2 - a2 * c1) / det
                s = -math.inf
                for q in range(n):
                    v = ga[q] * x + gb[q] * y + gc[q]
                    if v > s:
                        s = v
                        if s >= best:
                            break
                if s < best:
                    best, bx, by = s, x, y
    return bx, by, best
