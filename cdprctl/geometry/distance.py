"""Closest points between the shapes of the interference check (issue 67), compiled: segment
against segment, segment against a box, segment against a plane's solid side, and a box of the
platform's body against an obstacle of the cell (a box, a plane). Scalars in, scalars out:
nothing here allocates, so ``interference_kernel`` (``interference.py``) may call them in the
control cycle. Distances m, **signed** wherever a solid is met: 0 touching, negative overlapping
— a cable through a box or a box in a box by how deep, the least translation that takes one out
of the other (the separating-axis test over the candidate axes of two convex polyhedra: the face
normals of each and the cross products of their edges; Ericson 2005, §4.4 and §5.5), a box in a
plane's solid side by its deepest corner's depth — so that a cable or a platform already in a
fixture may leave it and never go deeper, where a 0 said nothing of how deep. A cable against a
cable is unsigned. A box is a row of 15 floats: centre, rotation row-major (box axes → the row's
frame), half extents."""

from __future__ import annotations

import math

from numba import njit

#: m²: a segment shorter than 1 nm is a point
_POINT2 = 1e-18
#: sin²θ below which two segments are parallel (θ < 1 µrad)
_PARALLEL = 1e-12

#: the cycle's kernels: no reference counting (their array arguments passed as they are, no
#: block per call: ``numerics.cycle_kernel``), the GIL released
interference_njit = njit(cache=True, nogil=True, _nrt=False)  # type: ignore[call-overload]


@interference_njit
def to_base(p, R, x, y, z):  # pragma: no cover - compiled
    """The platform-frame point ``(x, y, z)`` (m) in the base frame at the pose ``p``, ``R``."""
    return (p[0] + R[0, 0] * x + R[0, 1] * y + R[0, 2] * z,
            p[1] + R[1, 0] * x + R[1, 1] * y + R[1, 2] * z,
            p[2] + R[2, 0] * x + R[2, 1] * y + R[2, 2] * z)  # fmt: skip


@interference_njit
def _clamp01(x):  # pragma: no cover - compiled
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


@interference_njit
def segment_segment(
    p0x, p0y, p0z, p1x, p1y, p1z, q0x, q0y, q0z, q1x, q1y, q1z
):  # pragma: no cover - compiled
    """``(d, s, t)``: the least distance (m) between the segments ``P0 P1`` and ``Q0 Q1`` and
    the parameters of its points ``P0 + s (P1 − P0)``, ``Q0 + t (Q1 − Q0)`` (Ericson 2005,
    §5.1.9): a segment shorter than 1 nm taken as its point; parallel segments (sin²θ <
    1e-12) with ``s = 0`` and ``t`` clamped, then ``s`` again for the clamped ``t``."""
    d1x, d1y, d1z = p1x - p0x, p1y - p0y, p1z - p0z
    d2x, d2y, d2z = q1x - q0x, q1y - q0y, q1z - q0z
    rx, ry, rz = p0x - q0x, p0y - q0y, p0z - q0z
    a = d1x * d1x + d1y * d1y + d1z * d1z
    e = d2x * d2x + d2y * d2y + d2z * d2z
    f = d2x * rx + d2y * ry + d2z * rz
    if a <= _POINT2 and e <= _POINT2:
        s, t = 0.0, 0.0
    elif a <= _POINT2:
        s, t = 0.0, _clamp01(f / e)
    else:
        c = d1x * rx + d1y * ry + d1z * rz
        if e <= _POINT2:
            s, t = _clamp01(-c / a), 0.0
        else:
            b = d1x * d2x + d1y * d2y + d1z * d2z
            denom = a * e - b * b
            s = _clamp01((b * f - c * e) / denom) if denom > _PARALLEL * a * e else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t, s = 0.0, _clamp01(-c / a)
            elif t > 1.0:
                t, s = 1.0, _clamp01((b - c) / a)
    wx = rx + s * d1x - t * d2x
    wy = ry + s * d1y - t * d2y
    wz = rz + s * d1z - t * d2z
    return math.sqrt(wx * wx + wy * wy + wz * wz), s, t


@interference_njit
def _box_slope(ox, oy, oz, dx, dy, dz, hx, hy, hz, t):  # pragma: no cover - compiled
    """Half the derivative in ``t`` of the squared distance from ``o + t d`` to the box
    ``|x| <= h`` (box frame): ``Σ d_k (s_k − clamp(s_k))``, non-decreasing in ``t``."""
    g = 0.0
    for o, d, h in ((ox, dx, hx), (oy, dy, hy), (oz, dz, hz)):
        s = o + t * d
        if s > h:
            g += d * (s - h)
        elif s < -h:
            g += d * (s + h)
    return g


@interference_njit
def _push(nx, ny, nz, lo, hi, r, best, ux, uy, uz):  # pragma: no cover - compiled
    """The separating-axis step: along the unit axis ``n``, where one shape spans ``[lo,
    hi]`` and the other ``[−r, r]``, the shorter way out (``lo`` past ``r`` along ``+n``, or
    ``hi`` past ``−r`` along ``−n``) if it is shorter than ``best``: ``(depth, u)``, ``u``
    the unit way the first shape goes."""
    up, down = r - lo, hi + r
    if up <= down and up < best:
        return up, nx, ny, nz
    if down < up and down < best:
        return down, -nx, -ny, -nz
    return best, ux, uy, uz


@interference_njit
def _unit(k):  # pragma: no cover - compiled
    """The unit vector along axis ``k`` (0, 1, 2)."""
    return (1.0 if k == 0 else 0.0), (1.0 if k == 1 else 0.0), (1.0 if k == 2 else 0.0)


@interference_njit
def _segment_in_box(ox, oy, oz, dx, dy, dz, hx, hy, hz):  # pragma: no cover - compiled
    """``(−depth, a, q)`` of the segment ``o + t d`` (``t`` in [0, 1]) overlapping the box
    ``|x| <= h`` (box frame): ``depth`` (m) the least translation that takes it out, over
    the box's three face normals and the segment's direction across each of the box's edges
    (the faces of their Minkowski sum); ``a`` the segment's end deepest against that way out,
    ``q`` where it goes to (``a`` + depth × the way)."""
    best, ux, uy, uz = math.inf, 0.0, 0.0, 1.0
    ex, ey, ez = ox + dx, oy + dy, oz + dz
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    for k in range(6):
        if k < 3:  # the box's face normal k
            nx, ny, nz = _unit(k)
        else:  # d × the box's axis k − 3
            ax, ay, az = _unit(k - 3)
            nx, ny, nz = dy * az - dz * ay, dz * ax - dx * az, dx * ay - dy * ax
            norm = math.sqrt(nx * nx + ny * ny + nz * nz)
            if norm <= 1e-9 * length:
                continue  # along that axis (or a point): the face normals have it
            nx, ny, nz = nx / norm, ny / norm, nz / norm
        s0, s1 = nx * ox + ny * oy + nz * oz, nx * ex + ny * ey + nz * ez
        r = hx * abs(nx) + hy * abs(ny) + hz * abs(nz)
        best, ux, uy, uz = _push(nx, ny, nz, min(s0, s1), max(s0, s1), r, best, ux, uy, uz)
    deep = (ux * ox + uy * oy + uz * oz) > (ux * ex + uy * ey + uz * ez)
    ax, ay, az = (ex, ey, ez) if deep else (ox, oy, oz)
    return 0.0 - best, ax, ay, az, ax + best * ux, ay + best * uy, az + best * uz  # no −0.0


@interference_njit
def segment_box(boxes, row, sx, sy, sz, fx, fy, fz):  # pragma: no cover - compiled
    """``(d, a, q)`` flattened: the least distance (m) between the segment ``S F`` and box
    ``row`` of ``boxes`` (all in the box row's frame), its point ``a`` on the segment and ``q``
    on the box (same frame). See the module's docstring for the method."""
    cx, cy, cz = boxes[row, 0], boxes[row, 1], boxes[row, 2]
    hx, hy, hz = boxes[row, 12], boxes[row, 13], boxes[row, 14]
    # into the box's own frame: x' = Rᵀ (x − c), R = boxes[row, 3:12] row-major
    ux, uy, uz = sx - cx, sy - cy, sz - cz
    vx, vy, vz = fx - cx, fy - cy, fz - cz
    r0, r1, r2 = boxes[row, 3], boxes[row, 4], boxes[row, 5]
    r3, r4, r5 = boxes[row, 6], boxes[row, 7], boxes[row, 8]
    r6, r7, r8 = boxes[row, 9], boxes[row, 10], boxes[row, 11]
    ox = r0 * ux + r3 * uy + r6 * uz
    oy = r1 * ux + r4 * uy + r7 * uz
    oz = r2 * ux + r5 * uy + r8 * uz
    dx = r0 * vx + r3 * vy + r6 * vz - ox
    dy = r1 * vx + r4 * vy + r7 * vz - oy
    dz = r2 * vx + r5 * vy + r8 * vz - oz
    lo, g_lo = 0.0, _box_slope(ox, oy, oz, dx, dy, dz, hx, hy, hz, 0.0)
    hi, g_hi = 1.0, _box_slope(ox, oy, oz, dx, dy, dz, hx, hy, hz, 1.0)
    if g_lo >= 0.0:
        t = 0.0
    elif g_hi <= 0.0:
        t = 1.0
    else:  # the root lies on the one linear piece between the last break below and first above
        for o, d, h in ((ox, dx, hx), (oy, dy, hy), (oz, dz, hz)):
            if d != 0.0:
                for face in (h, -h):
                    tb = (face - o) / d
                    if lo < tb < hi:
                        gb = _box_slope(ox, oy, oz, dx, dy, dz, hx, hy, hz, tb)
                        if gb <= 0.0:
                            lo, g_lo = tb, gb
                        else:
                            hi, g_hi = tb, gb
        t = lo + (hi - lo) * (-g_lo / (g_hi - g_lo))
    px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
    qx, qy, qz = min(hx, max(-hx, px)), min(hy, max(-hy, py)), min(hz, max(-hz, pz))
    d = math.sqrt((px - qx) ** 2 + (py - qy) ** 2 + (pz - qz) ** 2)
    if d == 0.0:  # in the box: how deep, and the way out (``a`` the deepest end, ``q`` out)
        depth, ax, ay, az, bx, by, bz = _segment_in_box(ox, oy, oz, dx, dy, dz, hx, hy, hz)
        if depth < 0.0:  # touching only (0): the point of contact as it is
            d, px, py, pz, qx, qy, qz = depth, ax, ay, az, bx, by, bz
    # back to the row's frame: x = c + R x'
    return (d,
            cx + r0 * px + r1 * py + r2 * pz,
            cy + r3 * px + r4 * py + r5 * pz,
            cz + r6 * px + r7 * py + r8 * pz,
            cx + r0 * qx + r1 * qy + r2 * qz,
            cy + r3 * qx + r4 * qy + r5 * qz,
            cz + r6 * qx + r7 * qy + r8 * qz)  # fmt: skip


@interference_njit
def segment_plane(planes, row, bx, by, bz, ex, ey, ez):  # pragma: no cover - compiled
    """``(d, a, q)`` flattened: the least distance (m) between the segment ``B E`` and the
    solid side of plane ``row`` (``n·x <= d``), its point ``a`` on the segment (the end
    nearest, or where the segment crosses the plane) and ``q`` on the plane."""
    nx, ny, nz, off = planes[row, 0], planes[row, 1], planes[row, 2], planes[row, 3]
    sb = nx * bx + ny * by + nz * bz - off
    se = nx * ex + ny * ey + nz * ez - off
    t = 0.0 if sb <= se else 1.0
    lowest = min(sb, se)
    if lowest < 0.0 and max(sb, se) > 0.0:
        t = sb / (sb - se)  # where it crosses
    ax, ay, az = bx + t * (ex - bx), by + t * (ey - by), bz + t * (ez - bz)
    h = nx * ax + ny * ay + nz * az - off
    return max(lowest, 0.0), ax, ay, az, ax - h * nx, ay - h * ny, az - h * nz


@interference_njit
def to_platform(p, R, x, y, z):  # pragma: no cover - compiled
    """The base-frame point ``(x, y, z)`` (m) in the platform frame: ``Rᵀ (x − p)``."""
    vx, vy, vz = x - p[0], y - p[1], z - p[2]
    return (R[0, 0] * vx + R[1, 0] * vy + R[2, 0] * vz,
            R[0, 1] * vx + R[1, 1] * vy + R[2, 1] * vz,
            R[0, 2] * vx + R[1, 2] * vy + R[2, 2] * vz)  # fmt: skip


@interference_njit
def box_point(boxes, row, u0, u1, u2):  # pragma: no cover - compiled
    """The point ``u`` of box ``row``'s own frame in the row's frame: ``c + R u``."""
    return (boxes[row, 0] + boxes[row, 3] * u0 + boxes[row, 4] * u1 + boxes[row, 5] * u2,
            boxes[row, 1] + boxes[row, 6] * u0 + boxes[row, 7] * u1 + boxes[row, 8] * u2,
            boxes[row, 2] + boxes[row, 9] * u0 + boxes[row, 10] * u1
            + boxes[row, 11] * u2)  # fmt: skip


@interference_njit
def box_edge(boxes, row, e):  # pragma: no cover - compiled
    """Edge ``e`` (0-11) of box ``row``, its two ends in the box's own frame: it runs along
    axis ``e // 4`` at the corners ``±h`` of the other two (bits 0 and 1 of ``e``)."""
    hx, hy, hz = boxes[row, 12], boxes[row, 13], boxes[row, 14]
    a = 1.0 if e & 1 else -1.0
    b = 1.0 if e & 2 else -1.0
    axis = e // 4
    if axis == 0:
        return -hx, a * hy, b * hz, hx, a * hy, b * hz
    if axis == 1:
        return a * hx, -hy, b * hz, a * hx, hy, b * hz
    return a * hx, b * hy, -hz, a * hx, b * hy, hz


@interference_njit
def box_plane(boxes, row, planes, plane, p, R):  # pragma: no cover - compiled
    """``(d, a, q)`` flattened: the least distance (m) between the body's box ``row``
    (platform frame) at the pose ``p``, ``R`` and the solid side of ``plane`` (base frame,
    ``n·x <= d``); ``a`` the box's corner deepest towards the plane, ``q`` its foot on the
    plane (base frame). That corner lies against the normal along each of the box's axes:
    its height ``n·c − d − Σ h_k |n·a_k|``, **signed**: negative, how deep the box is in the
    solid (a platform resting on the floor may then not be pushed deeper, where a 0 would
    say nothing of how deep)."""
    nx, ny, nz, off = planes[plane, 0], planes[plane, 1], planes[plane, 2], planes[plane, 3]
    # the normal in the platform frame, then along each of the box's axes
    wx = R[0, 0] * nx + R[1, 0] * ny + R[2, 0] * nz
    wy = R[0, 1] * nx + R[1, 1] * ny + R[2, 1] * nz
    wz = R[0, 2] * nx + R[1, 2] * ny + R[2, 2] * nz
    g0 = boxes[row, 3] * wx + boxes[row, 6] * wy + boxes[row, 9] * wz
    g1 = boxes[row, 4] * wx + boxes[row, 7] * wy + boxes[row, 10] * wz
    g2 = boxes[row, 5] * wx + boxes[row, 8] * wy + boxes[row, 11] * wz
    u0 = -boxes[row, 12] if g0 > 0.0 else boxes[row, 12]
    u1 = -boxes[row, 13] if g1 > 0.0 else boxes[row, 13]
    u2 = -boxes[row, 14] if g2 > 0.0 else boxes[row, 14]
    x, y, z = box_point(boxes, row, u0, u1, u2)
    ax, ay, az = to_base(p, R, x, y, z)
    h = nx * ax + ny * ay + nz * az - off
    return h, ax, ay, az, ax - h * nx, ay - h * ny, az - h * nz


@interference_njit
def _axis(boxes, row, k, R, turned):  # pragma: no cover - compiled
    """Box ``row``'s axis ``k`` (a unit vector: column ``k`` of its rotation) in the base
    frame: turned by ``R`` for a box of the platform's body (``turned``)."""
    x, y, z = boxes[row, 3 + k], boxes[row, 6 + k], boxes[row, 9 + k]
    if not turned:
        return x, y, z
    return (R[0, 0] * x + R[0, 1] * y + R[0, 2] * z,
            R[1, 0] * x + R[1, 1] * y + R[1, 2] * z,
            R[2, 0] * x + R[2, 1] * y + R[2, 2] * z)  # fmt: skip


@interference_njit
def _radius(boxes, row, R, turned, nx, ny, nz):  # pragma: no cover - compiled
    """Half the extent (m) of box ``row`` along the unit ``n`` (base frame)."""
    r = 0.0
    for k in range(3):
        ax, ay, az = _axis(boxes, row, k, R, turned)
        r += boxes[row, 12 + k] * abs(nx * ax + ny * ay + nz * az)
    return r


@interference_njit
def _box_in_box(boxes, row, obstacle, p, R):  # pragma: no cover - compiled
    """``(−depth, a, q)`` of the body's box ``row`` (platform frame, at ``p``, ``R``)
    overlapping the obstacle's box (base frame): ``depth`` (m) the least translation that
    takes the body's box out, over the 15 candidate axes (each box's three face normals, the
    nine cross products of their axes); ``a`` the body's corner deepest against that way out,
    ``q`` where it goes to (``a`` + depth × the way; base frame)."""
    bx, by, bz = to_base(p, R, boxes[row, 0], boxes[row, 1], boxes[row, 2])
    cx, cy, cz = boxes[obstacle, 0] - bx, boxes[obstacle, 1] - by, boxes[obstacle, 2] - bz
    best, ux, uy, uz = math.inf, 0.0, 0.0, 1.0
    for k in range(15):
        if k < 3:
            nx, ny, nz = _axis(boxes, row, k, R, True)
        elif k < 6:
            nx, ny, nz = _axis(boxes, obstacle, k - 3, R, False)
        else:  # the body's axis (k − 6) // 3 across the obstacle's (k − 6) % 3
            ax, ay, az = _axis(boxes, row, (k - 6) // 3, R, True)
            ex, ey, ez = _axis(boxes, obstacle, (k - 6) % 3, R, False)
            nx, ny, nz = ay * ez - az * ey, az * ex - ax * ez, ax * ey - ay * ex
            norm = math.sqrt(nx * nx + ny * ny + nz * nz)
            if norm <= 1e-9:
                continue  # parallel axes: the face normals have it
            nx, ny, nz = nx / norm, ny / norm, nz / norm
        mine = _radius(boxes, row, R, True, nx, ny, nz)
        s = -(nx * cx + ny * cy + nz * cz)  # the body's centre along n, the obstacle's at 0
        best, ux, uy, uz = _push(nx, ny, nz, s - mine, s + mine,
                                 _radius(boxes, obstacle, R, False, nx, ny, nz), best, ux, uy,
                                 uz)  # fmt: skip
    for k in range(3):  # the corner deepest against the way out
        ax, ay, az = _axis(boxes, row, k, R, True)
        h = boxes[row, 12 + k] if ux * ax + uy * ay + uz * az < 0.0 else -boxes[row, 12 + k]
        bx, by, bz = bx + h * ax, by + h * ay, bz + h * az
    return 0.0 - best, bx, by, bz, bx + best * ux, by + best * uy, bz + best * uz  # no −0.0


@interference_njit
def box_box(boxes, row, obstacle, p, R):  # pragma: no cover - compiled
    """``(d, a, q)`` flattened: the least distance (m) between the body's box ``row``
    (platform frame) at the pose ``p``, ``R`` and the obstacle's box ``obstacle`` (base
    frame); ``a`` on the body's box, ``q`` on the obstacle's (base frame).

    Two disjoint convex polyhedra are closest at a vertex against a face, an edge against an
    edge, or degenerate cases of those (Ericson 2005, §5.5): each of the 24 edges (12 a box)
    against the other box, solid (``segment_box``), covers them all. Overlapping ones share a
    vertex of the overlap, which is a vertex of one inside the other or an edge of one
    through a face of the other: some edge meets the other box. Then the depth, signed
    (``_box_in_box``)."""
    best, ax, ay, az, qx, qy, qz = math.inf, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for e in range(24):
        mine = e < 12  # the body's edges (base frame) against the obstacle, then the other way
        edge, solid = (row, obstacle) if mine else (obstacle, row)
        u0, u1, u2, v0, v1, v2 = box_edge(boxes, edge, e % 12)
        sx, sy, sz = box_point(boxes, edge, u0, u1, u2)
        fx, fy, fz = box_point(boxes, edge, v0, v1, v2)
        if mine:
            sx, sy, sz = to_base(p, R, sx, sy, sz)
            fx, fy, fz = to_base(p, R, fx, fy, fz)
        else:  # the obstacle's edge into the platform frame, where the body's box is
            sx, sy, sz = to_platform(p, R, sx, sy, sz)
            fx, fy, fz = to_platform(p, R, fx, fy, fz)
        d, a0, a1, a2, q0, q1, q2 = segment_box(boxes, solid, sx, sy, sz, fx, fy, fz)
        if d < best:
            best = d
            if mine:
                ax, ay, az, qx, qy, qz = a0, a1, a2, q0, q1, q2
            else:  # the point on the body is the box's, the obstacle's the edge's
                ax, ay, az = to_base(p, R, q0, q1, q2)
                qx, qy, qz = to_base(p, R, a0, a1, a2)
    if best <= 0.0:
        return _box_in_box(boxes, row, obstacle, p, R)
    return best, ax, ay, az, qx, qy, qz
