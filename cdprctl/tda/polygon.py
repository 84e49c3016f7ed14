"""The feasible polygon of a redundancy-2 robot and 2-D optimisation over it.

Picard et al. 2020, eq. (6): ``{λ ∈ R² | t_min <= t0 + N λ <= t_max}``, a convex polygon, the
intersection of m strips (one per cable). It is built by clipping a bounding square with the
2m half-planes (Sutherland-Hodgman), in plain Python floats: at this size (8 strips, polygons of
4-8 vertices) numpy's per-call overhead would cost more than the arithmetic.

Vertices are ``(x, y)`` tuples in counter-clockwise order.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cdprctl.rotation import FloatArray

Point = tuple[float, float]


def _clip_strip(poly: list[Point], ax: float, ay: float, lo: float, hi: float) -> list[Point]:
    """Part of the convex polygon ``poly`` where ``lo <= ax·x + ay·y <= hi`` (one
    Sutherland-Hodgman pass for both sides of the strip)."""
    s = [ax * x + ay * y for x, y in poly]
    if min(s) >= lo and max(s) <= hi:
        return poly
    out: list[Point] = []
    px, py = poly[-1]
    sp = s[-1]
    for (qx, qy), sq in zip(poly, s, strict=True):
        # the part u in [u0, u1] of the edge P + u (Q − P) inside the strip
        ds = sq - sp
        if ds == 0.0:
            if lo <= sp <= hi:
                out.append((qx, qy))
        else:
            ua, ub = (lo - sp) / ds, (hi - sp) / ds
            if ua > ub:
                ua, ub = ub, ua
            u0 = ua if ua > 0.0 else 0.0
            u1 = ub if ub < 1.0 else 1.0
            if u0 <= u1:
                if u0 > 0.0:  # entering: the crossing point
                    out.append((px + u0 * (qx - px), py + u0 * (qy - py)))
                if u1 < 1.0:  # leaving before Q
                    out.append((px + u1 * (qx - px), py + u1 * (qy - py)))
                else:
                    out.append((qx, qy))
        px, py, sp = qx, qy, sq
    return out


def _parallelogram(
    a: tuple[float, float],
    lo_a: float,
    hi_a: float,
    b: tuple[float, float],
    lo_b: float,
    hi_b: float,
) -> list[Point]:
    """The intersection of two non-parallel strips, counter-clockwise."""
    det = a[0] * b[1] - a[1] * b[0]
    pts = [
        ((sa * b[1] - sb * a[1]) / det, (a[0] * sb - b[0] * sa) / det)
        for sa, sb in ((lo_a, lo_b), (hi_a, lo_b), (hi_a, hi_b), (lo_a, hi_b))
    ]
    return pts if det > 0.0 else pts[::-1]


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
    n0 = N[:, 0].tolist()
    n1 = N[:, 1].tolist()
    c = t0.tolist()
    lo = [li - ci - eps for li, ci in zip(t_lo.tolist(), c, strict=True)]
    hi = [hi_ - ci + eps for hi_, ci in zip(t_hi.tolist(), c, strict=True)]
    m = len(c)
    # first strip: the longest normal; second: the most perpendicular to it
    norms = [math.hypot(n0[i], n1[i]) for i in range(m)]
    i0 = max(range(m), key=norms.__getitem__)
    best, i1 = -1.0, -1
    for j in range(m):
        if j != i0 and norms[j] > 0.0:
            sin = abs(n0[i0] * n1[j] - n1[i0] * n0[j]) / (norms[i0] * norms[j])
            if sin > best:
                best, i1 = sin, j
    if best < 1e-12:  # every strip parallel: N is not of rank 2
        return []
    if lo[i0] > hi[i0] or lo[i1] > hi[i1]:
        return []
    poly = _parallelogram((n0[i0], n1[i0]), lo[i0], hi[i0], (n0[i1], n1[i1]), lo[i1], hi[i1])
    for i in range(m):
        if i in (i0, i1):
            continue
        if norms[i] == 0.0:  # a cable the redundancy cannot change: in bounds or not at all
            if not lo[i] <= 0.0 <= hi[i]:
                return []
            continue
        poly = _clip_strip(poly, n0[i], n1[i], lo[i], hi[i])
        if not poly:
            return poly
    return _dedupe(poly)


def _dedupe(poly: list[Point], tol: float = 1e-12) -> list[Point]:
    """Drop vertices that repeat the previous one (clipping through a vertex makes them)."""
    if len(poly) < 2:
        return poly
    scale = max(1.0, max(abs(v) for p in poly for v in p))
    tol *= scale
    out = [poly[0]]
    for p in poly[1:]:
        q = out[-1]
        if abs(p[0] - q[0]) > tol or abs(p[1] - q[1]) > tol:
            out.append(p)
    if len(out) > 1:
        p, q = out[-1], out[0]
        if abs(p[0] - q[0]) <= tol and abs(p[1] - q[1]) <= tol:
            out.pop()
    return out


def area_centroid(poly: Sequence[Point]) -> tuple[float, Point]:
    """Area and area centroid of a polygon, closing edge included (shoelace formula).

    A degenerate polygon (a segment or a point, area ~ 0) returns the mean of its vertices.
    """
    n = len(poly)
    if n == 0:
        return 0.0, (math.nan, math.nan)
    a2 = cx = cy = 0.0
    x0, y0 = poly[0]  # shift to the first vertex: less cancellation for far polygons
    px, py = 0.0, 0.0
    for i in range(1, n + 1):
        qx, qy = poly[i % n]
        qx -= x0
        qy -= y0
        cross = px * qy - qx * py
        a2 += cross
        cx += (px + qx) * cross
        cy += (py + qy) * cross
        px, py = qx, qy
    scale = max(1e-300, max(abs(x - x0) + abs(y - y0) for x, y in poly))
    if abs(a2) <= 1e-12 * scale * scale:
        mx = sum(p[0] for p in poly) / n
        my = sum(p[1] for p in poly) / n
        return 0.0, (mx, my)
    return 0.5 * abs(a2), (x0 + cx / (3.0 * a2), y0 + cy / (3.0 * a2))


def contains(poly: Sequence[Point], x: float, y: float, tol: float = 1e-9) -> bool:
    """True when ``(x, y)`` is inside the counter-clockwise convex polygon (within ``tol``)."""
    n = len(poly)
    if n == 0:
        return False
    if n == 1:
        return abs(poly[0][0] - x) <= tol and abs(poly[0][1] - y) <= tol
    px, py = poly[-1]
    for qx, qy in poly:
        ex, ey = qx - px, qy - py
        norm = math.hypot(ex, ey)
        if norm > 0.0 and (ex * (y - py) - ey * (x - px)) / norm < -tol:
            return False
        px, py = qx, qy
    return True


def closest_point(poly: Sequence[Point], x: float, y: float) -> Point:
    """Point of the convex polygon closest to ``(x, y)`` (Euclidean)."""
    return min_quadratic(poly, 1.0, 0.0, 1.0, -x, -y)


def min_quadratic(
    poly: Sequence[Point], h11: float, h12: float, h22: float, g1: float, g2: float
) -> Point:
    """Minimiser over the convex polygon of ``½ λᵀ H λ + gᵀ λ`` (``H`` symmetric positive
    definite). Interior minimum if inside, else the best point of the edges (the function is
    convex, so its constrained minimum lies on the boundary)."""
    det = h11 * h22 - h12 * h12
    ux = -(h22 * g1 - h12 * g2) / det
    uy = -(-h12 * g1 + h11 * g2) / det
    if contains(poly, ux, uy, tol=0.0):
        return ux, uy
    n = len(poly)
    if n == 1:
        return poly[0]
    best = poly[0]
    best_f = math.inf
    px, py = poly[-1]
    for qx, qy in poly:
        dx, dy = qx - px, qy - py
        hdx, hdy = h11 * dx + h12 * dy, h12 * dx + h22 * dy
        curv = dx * hdx + dy * hdy
        # gradient at P along d: dᵀ(H P + g)
        slope = dx * (h11 * px + h12 * py + g1) + dy * (h12 * px + h22 * py + g2)
        s = 0.0 if curv <= 0.0 else min(1.0, max(0.0, -slope / curv))
        x, y = px + s * dx, py + s * dy
        f = 0.5 * (h11 * x * x + 2.0 * h12 * x * y + h22 * y * y) + g1 * x + g2 * y
        if f < best_f:
            best_f, best = f, (x, y)
        px, py = qx, qy
    return best


def min_linear(poly: Sequence[Point], c1: float, c2: float) -> Point:
    """Vertex minimising ``c1 x + c2 y`` (a linear objective's optimum is at a vertex)."""
    return min(poly, key=lambda p: c1 * p[0] + c2 * p[1])


def least_violating(
    N: FloatArray, t0: FloatArray, t_lo: FloatArray, t_hi: FloatArray
) -> tuple[FloatArray, float]:
    """``λ`` minimising the largest bound violation ``max_i max(lo_i − t_i, t_i − hi_i)``.

    For an infeasible wrench (empty polygon). The objective is the maximum of 2m affine
    functions of λ; its minimum is where three of them are equal (a 2-D linear programme):
    every triple is solved by Cramer's rule, vectorised, and the best kept. Returns
    ``(λ, s)`` with ``s`` (N) the largest violation there.
    """
    m = N.shape[0]
    # g_k(λ) = G[k,0] λx + G[k,1] λy + G[k,2]
    G = np.empty((2 * m, 3))
    G[:m, :2] = -N
    G[:m, 2] = t_lo - t0
    G[m:, :2] = N
    G[m:, 2] = t0 - t_hi
    idx = _triples(2 * m)
    A = G[idx]  # (T, 3, 3): rows [a, b, c] of the three functions
    # a λx + b λy − s = −c for each of the three rows
    M = np.concatenate([A[:, :, :2], -np.ones((len(idx), 3, 1))], axis=2)
    rhs = -A[:, :, 2]
    det = np.linalg.det(M)
    ok = np.abs(det) > 1e-12 * np.abs(M).max()
    sol = np.linalg.solve(M[ok], rhs[ok][:, :, None])[:, :, 0]  # (T', 3)
    values = sol[:, :2] @ G[:, :2].T + G[:, 2]  # (T', 2m)
    worst = values.max(axis=1)
    k = int(np.argmin(worst))
    return sol[k, :2].copy(), float(worst[k])


_TRIPLES: dict[int, np.ndarray] = {}


def _triples(n: int) -> np.ndarray:
    if n not in _TRIPLES:
        i, j, k = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
        mask = (i < j) & (j < k)
        _TRIPLES[n] = np.stack([i[mask], j[mask], k[mask]], axis=1)
    return _TRIPLES[n]
