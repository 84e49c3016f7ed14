"""Interference at one pose: the least distance between every pair of cables, between every
cable and the platform's body, between every cable and each obstacle of the cell (issue 67).

The model is Perreault, Cardou, Gosselin and Otis 2010 ("Geometric determination of the
interference-free constant-orientation workspace of parallel cable-driven mechanisms", ASME J.
Mechanisms Robotics 2(3)): each cable a straight segment, the platform a rigid body of convex
parts. Where they derive the workspace's boundary in closed form, this measures one pose, fast
enough for every cycle, and says by how much it is clear:

* **A cable** is the segment from its attachment ``B_i = p + R b_i`` to its exit point at the
  frame, both exactly as the inverse kinematics computes them (``KinematicsData.rbT`` and
  ``exitT``: the swivel pulley's tangent point where there is one,
  ``cdprctl/geometry/kinematics.py``). The check reads the kinematics' arrays after
  ``inverse_kinematics`` at the same pose.
* **Cable against cable**: the closest points of two segments, Ericson, *Real-Time Collision
  Detection*, 2005, §5.1.9 (``ClosestPtSegmentSegment``), which handles zero-length segments
  and parallel ones (there ``s = 0`` and the other parameter clamped: the distance between
  parallel segments is reached at an end of one of them). Pairs that share an anchor or an
  attachment *by design* (seed000's two cables per frame corner) touch there at every pose and
  are not checked: detected when their anchors, or their attachments, are within 1 µm
  (``Interference.excluded``).
* **Cable against the platform's body** (boxes in the platform frame, ``[[platform.body.boxes]]``):
  a cable's own attachment is on or in the body, so a cable is measured from
  ``attachment_exclusion`` (m, ``[interference]``) along it from its attachment to its exit
  point: the part within that distance of the attachment (the eyelet, its bracket) is not
  counted; beyond it, a cable that runs into the body, or across an edge of it, is at 0. The
  same rule holds for every box of the body, the one the attachment is on included.
* **Cable against an obstacle** (base frame, ``[[cell.obstacles]]``): a box, or a plane whose
  solid side is behind its normal (the floor, a facade). The whole segment counts.
* **Segment against box**: the squared distance from the point ``s(t)`` of the segment to the
  box is convex and piecewise quadratic in ``t``, its derivative piecewise linear and
  non-decreasing, with a break where a coordinate crosses a face's plane (at most 6). The
  minimum is at ``t = 0``, ``t = 1``, or the root of the derivative, found exactly on the one
  piece where it changes sign (no iteration, no sort); the box's closest point is the clamp
  of ``s(t)``. A segment through the box is at 0.

Distances are m (0 when touching or crossing), points in the base frame. ``Interference``
keeps every array; ``interference_kernel`` writes into them and allocates nothing (a
``cycle_kernel``-style kernel, without reference counting, and ``nogil`` so that a path's or
the workspace's check may run beside the loop's thread).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from cdprctl.core.numerics import kernel_args
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.kinematics import CableLayout, KinematicsData, inverse_kinematics
from cdprctl.model.interference import Box, InterferenceConfig, Plane

#: a check's kind (``Interference.checks[:, 0]``)
CABLE, BODY, OBSTACLE = 0, 1, 2
#: the shape a check measures the cable against (``checks[:, 3]``)
SEGMENT, BOX, PLANE = 0, 1, 2
#: m: anchors or attachments this close are one point by design (the pair is not checked)
SHARED = 1e-6
#: m²: a segment shorter than 1 nm is a point
_POINT2 = 1e-18
#: sin²θ below which two segments are parallel (θ < 1 µrad)
_PARALLEL = 1e-12

#: the cycle's kernels: no reference counting (their array arguments passed as they are, no
#: block per call: ``numerics.cycle_kernel``), the GIL released
interference_njit = njit(cache=True, nogil=True, _nrt=False)  # type: ignore[call-overload]


class InterferenceArrays(NamedTuple):
    """The arrays of one :class:`Interference`, as ``interference_kernel`` takes them
    (``kernel_args``). Inputs: ``checks`` (n, 5) int64 — kind, cable ``i``, the other (cable
    ``j``, body part ``k``, obstacle ``k``), shape (``SEGMENT``, ``BOX``, ``PLANE``), row in
    ``boxes``/``planes``; ``boxes`` (nb, 15): centre (m), rotation row-major (box → platform
    frame for a body's, → base frame for an obstacle's), half extents (m); ``planes`` (np, 4):
    unit normal, offset ``d`` (m: ``n·x = d`` on the plane, ``n·x > d`` free);
    ``exclusion`` (1,) m. Outputs: ``distance`` (n,) m, ``closest`` (n, 6) m, base frame —
    the point on cable ``i``, then the point on the other; ``best`` (1,) int64, the check of
    the least distance (the first of equals)."""

    checks: np.ndarray
    boxes: FloatArray
    planes: FloatArray
    exclusion: FloatArray
    distance: FloatArray
    closest: FloatArray
    best: np.ndarray


class Interference:
    """The interference checks of one robot and the results of the last pose (preallocated:
    :meth:`update` allocates nothing). ``checks`` lists them in order: every pair of cables not
    excluded (``i < j``), then each cable against each part of the body, then each cable
    against each obstacle."""

    def __init__(self, model: CableLayout, config: InterferenceConfig | None = None):
        cfg = config if config is not None else getattr(model, "interference", None)
        self.config = cfg if cfg is not None else InterferenceConfig()
        self.clearance = self.config.clearance  # m
        m = model.n_cables
        anchors, attach = np.asarray(model.anchors), np.asarray(model.attachments)
        self.excluded: list[tuple[int, int]] = []  # (i, j), 0-based: a shared point by design
        rows: list[tuple[int, int, int, int, int]] = []
        for i in range(m):
            for j in range(i + 1, m):
                if (np.linalg.norm(anchors[i] - anchors[j]) < SHARED
                        or np.linalg.norm(attach[i] - attach[j]) < SHARED):  # fmt: skip
                    self.excluded.append((i, j))
                else:
                    rows.append((CABLE, i, j, SEGMENT, 0))
        boxes: list[FloatArray] = []
        planes: list[FloatArray] = []
        body = self.config.body
        for k, part in enumerate(body):
            boxes.append(_box_row(part))
            rows += [(BODY, i, k, BOX, len(boxes) - 1) for i in range(m)]
        for k, obstacle in enumerate(self.config.obstacles):
            if isinstance(obstacle, Box):
                boxes.append(_box_row(obstacle))
                rows += [(OBSTACLE, i, k, BOX, len(boxes) - 1) for i in range(m)]
            else:
                planes.append(_plane_row(obstacle))
                rows += [(OBSTACLE, i, k, PLANE, len(planes) - 1) for i in range(m)]
        n = len(rows)
        self.checks = np.array(rows, dtype=np.int64).reshape(n, 5)
        self.distance = np.full(n, math.inf)  # m
        self.closest = np.zeros((n, 6))  # m, base frame: on cable i, on the other
        self.best = np.zeros(1, dtype=np.int64)
        self.arrays = kernel_args(
            InterferenceArrays(
                self.checks,
                np.array(boxes, dtype=float).reshape(len(boxes), 15),
                np.array(planes, dtype=float).reshape(len(planes), 4),
                np.array([self.config.attachment_exclusion]),
                self.distance,
                self.closest,
                self.best,
            )
        )
        self.cable_names = [str(getattr(c, "name", i + 1)) for i, c in
                            enumerate(getattr(model, "cables", range(m)))]  # fmt: skip
        self.body_names = [b.name for b in body]
        self.obstacle_names = [o.name for o in self.config.obstacles]

    def update(self, kin: KinematicsData) -> None:
        """Every distance at the pose of the last ``inverse_kinematics`` into ``kin`` (its
        ``position``, ``rotation``, ``rbT``, ``exitT``)."""
        interference_kernel(kin.arrays, kin.position, kin.rotation, self.arrays)

    @property
    def minimum(self) -> float:
        """m: the least distance of the last pose (``inf`` with nothing to check)."""
        return float(self.distance[self.best[0]]) if len(self.distance) else math.inf

    def describe(self, c: int | None = None) -> str:
        """Check ``c`` (default the least) in words: what against what, the distance (mm)."""
        if not len(self.distance):
            return "nothing to check"
        c = int(self.best[0]) if c is None else c
        return f"{self.name(c)}: {self.distance[c] * 1e3:.2f} mm"

    def name(self, c: int) -> str:
        """Check ``c`` in words: what against what."""
        kind, i, k = (int(x) for x in self.checks[c, :3])
        cable = self.cable_names
        if kind == CABLE:  # names that say "cable" already ("cable 6") are not repeated
            said = cable[i].startswith("cable") and cable[k].startswith("cable")
            return f"{cable[i]} and {cable[k]}" if said else f"cables {cable[i]} and {cable[k]}"
        if kind == BODY:
            return f"cable {cable[i]} and the platform's {self.body_names[k]}"
        return f"cable {cable[i]} and {self.obstacle_names[k]}"


def check_pose(model: CableLayout, position: FloatArray, rotation: FloatArray) -> Interference:
    """Convenience (allocating) form: every distance of ``model`` at a pose."""
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, position, rotation)
    out = Interference(model)
    out.update(kin)
    return out


def _box_row(box: Box) -> FloatArray:
    return np.concatenate([box.centre, np.asarray(box.rotation).ravel(), box.half_extents])


def _plane_row(plane: Plane) -> FloatArray:
    n = np.asarray(plane.normal, dtype=float)
    return np.array([n[0], n[1], n[2], float(n @ plane.point)])


@interference_njit
def interference_kernel(k, p, R, g):  # pragma: no cover - compiled
    """Every check of ``g`` (:class:`InterferenceArrays`) at the pose ``p`` (m, base frame),
    ``R`` (platform → base) whose inverse kinematics ``k`` (``KinArrays``) holds."""
    attach, rbT, exitT = k[1], k[4], k[5]
    checks, boxes, planes, exclusion, distance, closest, best = g
    best[0] = 0
    least = math.inf
    for c in range(checks.shape[0]):
        kind, i, other = checks[c, 0], checks[c, 1], checks[c, 2]
        shape, row = checks[c, 3], checks[c, 4]
        bx, by, bz = p[0] + rbT[0, i], p[1] + rbT[1, i], p[2] + rbT[2, i]
        ex, ey, ez = exitT[0, i], exitT[1, i], exitT[2, i]
        if shape == SEGMENT:
            j = other
            d, s, t = segment_segment(
                bx, by, bz, ex, ey, ez,
                p[0] + rbT[0, j], p[1] + rbT[1, j], p[2] + rbT[2, j],
                exitT[0, j], exitT[1, j], exitT[2, j],
            )  # fmt: skip
            _write(closest, c, bx + s * (ex - bx), by + s * (ey - by), bz + s * (ez - bz), 0)
            qx, qy, qz = p[0] + rbT[0, j], p[1] + rbT[1, j], p[2] + rbT[2, j]
            _write(closest, c, qx + t * (exitT[0, j] - qx), qy + t * (exitT[1, j] - qy),
                   qz + t * (exitT[2, j] - qz), 3)  # fmt: skip
        elif shape == BOX:
            if kind == BODY:  # platform frame: from the attachment b_i, less the exclusion
                sx, sy, sz = attach[i, 0], attach[i, 1], attach[i, 2]
                vx, vy, vz = ex - p[0], ey - p[1], ez - p[2]
                fx = R[0, 0] * vx + R[1, 0] * vy + R[2, 0] * vz
                fy = R[0, 1] * vx + R[1, 1] * vy + R[2, 1] * vz
                fz = R[0, 2] * vx + R[1, 2] * vy + R[2, 2] * vz
                length = math.sqrt((fx - sx) ** 2 + (fy - sy) ** 2 + (fz - sz) ** 2)
                if not length > exclusion[0]:  # nothing beyond the attachment's neighbourhood
                    distance[c] = math.inf
                    _write(closest, c, bx, by, bz, 0)
                    _write(closest, c, bx, by, bz, 3)
                    continue
                f = exclusion[0] / length
                sx, sy, sz = sx + f * (fx - sx), sy + f * (fy - sy), sz + f * (fz - sz)
            else:
                sx, sy, sz, fx, fy, fz = bx, by, bz, ex, ey, ez
            d, ax, ay, az, qx, qy, qz = segment_box(boxes, row, sx, sy, sz, fx, fy, fz)
            if kind == BODY:  # back to the base frame
                ax, ay, az = _to_base(p, R, ax, ay, az)
                qx, qy, qz = _to_base(p, R, qx, qy, qz)
            _write(closest, c, ax, ay, az, 0)
            _write(closest, c, qx, qy, qz, 3)
        else:
            d, ax, ay, az, qx, qy, qz = segment_plane(planes, row, bx, by, bz, ex, ey, ez)
            _write(closest, c, ax, ay, az, 0)
            _write(closest, c, qx, qy, qz, 3)
        distance[c] = d
        if d < least:
            least = d
            best[0] = c


@interference_njit
def _write(out, c, x, y, z, at):  # pragma: no cover - compiled
    out[c, at], out[c, at + 1], out[c, at + 2] = x, y, z


@interference_njit
def _to_base(p, R, x, y, z):  # pragma: no cover - compiled
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
