"""Interference at one pose: the least distance between every pair of cables, between every
cable and the platform's body, between every cable and each obstacle of the cell, and between
the platform's body and each obstacle (issue 67).

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
* **The platform's body against an obstacle**: each box of the body, whole, against each
  obstacle (``distance.box_box``, ``distance.box_plane``): the platform driven into a beam, a
  fixture or the floor, which no cable check sees.
* **Segment against box**: the squared distance from the point ``s(t)`` of the segment to the
  box is convex and piecewise quadratic in ``t``, its derivative piecewise linear and
  non-decreasing, with a break where a coordinate crosses a face's plane (at most 6). The
  minimum is at ``t = 0``, ``t = 1``, or the root of the derivative, found exactly on the one
  piece where it changes sign (no iteration, no sort); the box's closest point is the clamp
  of ``s(t)``. A segment through the box is at 0. (``distance.py`` holds these closest
  points; this module the checks of a robot and the kernel that runs them.)

Distances are m (0 when touching or crossing), points in the base frame. ``Interference``
keeps every array; ``interference_kernel`` writes into them and allocates nothing (a
``cycle_kernel``-style kernel, without reference counting, and ``nogil`` so that a path's or
the workspace's check may run beside the loop's thread).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cdprctl.core.numerics import kernel_args
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.distance import (
    box_box,
    box_plane,
    interference_njit,
    segment_box,
    segment_plane,
    segment_segment,
    to_base,
    to_platform,
)
from cdprctl.geometry.kinematics import CableLayout, KinematicsData, inverse_kinematics
from cdprctl.model.interference import Box, InterferenceConfig, Plane

#: a check's kind (``Interference.checks[:, 0]``): a cable against a cable, the platform's body
#: or an obstacle; the platform's body against an obstacle
CABLE, BODY, OBSTACLE, PLATFORM = 0, 1, 2, 3
#: the shape a check measures the cable against (``checks[:, 3]``)
SEGMENT, BOX, PLANE = 0, 1, 2
#: m: anchors or attachments this close are one point by design (the pair is not checked)
SHARED = 1e-6


class InterferenceArrays(NamedTuple):
    """The arrays of one :class:`Interference`, as ``interference_kernel`` takes them
    (``kernel_args``). Inputs: ``checks`` (n, 5) int64 — kind, cable ``i``, the other (cable
    ``j``, body part ``k``, obstacle ``k``), shape (``SEGMENT``, ``BOX``, ``PLANE``), row in
    ``boxes``/``planes``; ``boxes`` (nb, 15): centre (m), rotation row-major (box → platform
    frame for a body's, → base frame for an obstacle's), half extents (m); ``planes`` (np, 4):
    unit normal, offset ``d`` (m: ``n·x = d`` on the plane, ``n·x > d`` free);
    ``exclusion`` (1,) m. Outputs: ``distance`` (n,) m, ``closest`` (n, 6) m, base frame —
    the point on cable ``i``, then the point on the other; ``best`` (1,) int64, the check of
    the least distance plus its ``slack`` (the first of equals); ``slack`` (n,) m, an input:
    how far under the clearance each check may go (0 but for a motion that starts under it:
    :meth:`Interference.relax`)."""

    checks: np.ndarray
    boxes: FloatArray
    planes: FloatArray
    exclusion: FloatArray
    distance: FloatArray
    closest: FloatArray
    best: np.ndarray
    slack: FloatArray


class Interference:
    """The interference checks of one robot and the results of the last pose (preallocated:
    :meth:`update` allocates nothing). ``checks`` lists them in order: every pair of cables not
    excluded (``i < j``), then each cable against each part of the body, then each cable
    against each obstacle, then each part of the body against each obstacle (``PLATFORM``:
    column 1 the part, not a cable)."""

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
        body = self.config.body
        boxes = [_box_row(part) for part in body]  # the body's parts first: row k is part k
        planes: list[FloatArray] = []
        rows += [(BODY, i, k, BOX, k) for k in range(len(body)) for i in range(m)]
        against: list[tuple[int, int, int]] = []  # each obstacle: (k, shape, row)
        for k, obstacle in enumerate(self.config.obstacles):
            if isinstance(obstacle, Box):
                boxes.append(_box_row(obstacle))
                against.append((k, BOX, len(boxes) - 1))
            else:
                planes.append(_plane_row(obstacle))
                against.append((k, PLANE, len(planes) - 1))
        rows += [(OBSTACLE, i, k, shape, row) for k, shape, row in against for i in range(m)]
        rows += [(PLATFORM, b, k, shape, row) for k, shape, row in against
                 for b in range(len(body))]  # fmt: skip
        n = len(rows)
        self.checks = np.array(rows, dtype=np.int64).reshape(n, 5)
        self.distance = np.full(n, math.inf)  # m
        self.closest = np.zeros((n, 6))  # m, base frame: on cable i (body part i), the other
        self.best = np.zeros(1, dtype=np.int64)
        self.slack = np.zeros(n)  # m: see InterferenceArrays
        self.arrays = kernel_args(
            InterferenceArrays(
                self.checks,
                np.array(boxes, dtype=float).reshape(len(boxes), 15),
                np.array(planes, dtype=float).reshape(len(planes), 4),
                np.array([self.config.attachment_exclusion]),
                self.distance,
                self.closest,
                self.best,
                self.slack,
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
        """m: the least distance of the last pose (``inf`` with nothing to check); with a
        slack set, the distance of the check closest to its own floor (``effective``)."""
        # .item(): a Python float, no numpy scalar (the cycle's supervisor reads it)
        return self.distance.item(self.best.item(0)) if len(self.distance) else math.inf

    @property
    def effective(self) -> float:
        """m: the least distance plus its check's slack, to compare with the clearance
        (``minimum`` when no slack is set)."""
        if not len(self.distance):
            return math.inf
        c = self.best.item(0)
        return self.distance.item(c) + self.slack.item(c)

    def relax(self, limit: float, below: float | None = None) -> None:
        """Each check now under ``below`` (m, default ``limit``) may stay where it is but get
        no closer than ``limit`` asks: its slack ``limit − d`` (0 for the others), so that its
        distance plus its slack is ``limit`` here. A robot under the clearance may leave it,
        check by check: the checks that are clear keep the whole clearance. No allocation
        (the cycle's supervisor calls it): compiled."""
        relax_kernel(self.distance, self.slack, limit, limit if below is None else below)

    def describe(self, c: int | None = None) -> str:
        """Check ``c`` (default the least) in words: what against what, how far apart or how
        deep in each other (``distance_words``)."""
        if not len(self.distance):
            return "nothing to check"
        c = int(self.best[0]) if c is None else c
        return f"{self.name(c)}: {distance_words(float(self.distance[c]))}"

    def name(self, c: int) -> str:
        """Check ``c`` in words: what against what."""
        kind, i, k = (int(x) for x in self.checks[c, :3])
        cable = self.cable_names
        if kind == CABLE:  # names that say "cable" already ("cable 6") are not repeated
            said = cable[i].startswith("cable") and cable[k].startswith("cable")
            return f"{cable[i]} and {cable[k]}" if said else f"cables {cable[i]} and {cable[k]}"
        if kind == BODY:
            return f"cable {cable[i]} and the platform's {self.body_names[k]}"
        if kind == PLATFORM:
            return f"the platform's {self.body_names[i]} and {self.obstacle_names[k]}"
        return f"cable {cable[i]} and {self.obstacle_names[k]}"


def distance_words(d: float, digits: int = 2, apart: str = " apart") -> str:
    """A signed distance ``d`` (m) in words: "4.75 mm apart", or where the shapes overlap
    "overlapping by 12.00 mm" (how deep: ``distance.py``); ``digits`` decimals of mm, and
    what rounds to zero is "0.00 mm apart" (no "-0.00"); ``apart`` what follows a distance."""
    mm = round(d * 1e3, digits) + 0.0
    return f"{mm:.{digits}f} mm{apart}" if mm >= 0.0 else f"overlapping by {-mm:.{digits}f} mm"


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
    checks, boxes, planes, distance, closest, best, slack = g[0], g[1], g[2], g[4], g[5], g[6], g[7]
    best[0] = 0
    least = math.inf
    for c in range(checks.shape[0]):
        if checks[c, 0] == PLATFORM:  # body part ``i`` (its row in ``boxes``), an obstacle
            part, shape, row = checks[c, 1], checks[c, 3], checks[c, 4]
            if shape == BOX:
                d, ax, ay, az, qx, qy, qz = box_box(boxes, part, row, p, R)
            else:
                d, ax, ay, az, qx, qy, qz = box_plane(boxes, part, planes, row, p, R)
            _write(closest, c, ax, ay, az, 0)
            _write(closest, c, qx, qy, qz, 3)
        else:
            d = _cable_check(k, p, R, g, c)
        distance[c] = d
        if d + slack[c] < least:
            least = d + slack[c]
            best[0] = c


@interference_njit
def relax_kernel(distance, slack, limit, below):  # pragma: no cover - compiled
    """``slack`` (m) ``limit − d`` for each distance ``d`` under ``below``, else 0 (a NaN
    distance: 0)."""
    for c in range(distance.shape[0]):
        d = distance[c]
        slack[c] = max(limit - d, 0.0) if d < below else 0.0


@interference_njit
def _cable_check(k, p, R, g, c):  # pragma: no cover - compiled
    """Check ``c``, a cable against a cable, the body or an obstacle: its distance (m), its
    closest points written; ``inf`` for a cable no longer than ``attachment_exclusion``."""
    attach, rbT, exitT = k[1], k[4], k[5]
    checks, boxes, planes, exclusion, closest = g[0], g[1], g[2], g[3], g[5]
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
        return d
    if shape == PLANE:
        d, ax, ay, az, qx, qy, qz = segment_plane(planes, row, bx, by, bz, ex, ey, ez)
        _write(closest, c, ax, ay, az, 0)
        _write(closest, c, qx, qy, qz, 3)
        return d
    if kind == BODY:  # platform frame: from the attachment b_i, less the exclusion
        sx, sy, sz = attach[i, 0], attach[i, 1], attach[i, 2]
        fx, fy, fz = to_platform(p, R, ex, ey, ez)
        length = math.sqrt((fx - sx) ** 2 + (fy - sy) ** 2 + (fz - sz) ** 2)
        if not length > exclusion[0]:  # nothing beyond the attachment's neighbourhood
            _write(closest, c, bx, by, bz, 0)
            _write(closest, c, bx, by, bz, 3)
            return math.inf
        f = exclusion[0] / length
        sx, sy, sz = sx + f * (fx - sx), sy + f * (fy - sy), sz + f * (fz - sz)
    else:
        sx, sy, sz, fx, fy, fz = bx, by, bz, ex, ey, ez
    d, ax, ay, az, qx, qy, qz = segment_box(boxes, row, sx, sy, sz, fx, fy, fz)
    if kind == BODY:  # back to the base frame
        ax, ay, az = to_base(p, R, ax, ay, az)
        qx, qy, qz = to_base(p, R, qx, qy, qz)
    _write(closest, c, ax, ay, az, 0)
    _write(closest, c, qx, qy, qz, 3)
    return d


@interference_njit
def _write(out, c, x, y, z, at):  # pragma: no cover - compiled
    out[c, at], out[c, at + 1], out[c, at + 2] = x, y, z


