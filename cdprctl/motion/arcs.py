"""G2/G3 arcs as the chords the plan plays (``gcode.py`` reads the words; this is geometry).

Lengths in m, angles in rad. A plane is the pair of pose indices it spans, ordered so that
their cross product is the axis the arc turns about (G17: x, y about +z; G18: z, x about +y;
G19: y, z about +x), and G3 (counter-clockwise seen from that axis's positive end) turns the
positive way. The other coordinates (the helix's axis, roll, pitch, yaw) move in proportion
to the angle turned.
"""

from __future__ import annotations

import math

import numpy as np

from cdprctl.core.rotation import FloatArray

#: plane G code → (first, second) pose index: first × second is the axis the arc turns about
PLANES = {17: (0, 1), 18: (2, 0), 19: (1, 2)}
#: plane G code → the words of its centre's offsets (first, second) and the one it refuses
OFFSET_WORDS = {17: ("I", "J", "K"), 18: ("K", "I", "J"), 19: ("J", "K", "I")}
SAME_POINT = 1e-9  # m: an end this close to the start (in the plane) closes a full circle


class ArcError(ValueError):
    """An arc that cannot be drawn; the message names the values and the rule (the reader
    adds the line)."""


def centre_from_radius(
    start: FloatArray, end: FloatArray, radius: float, clockwise: bool, tolerance: float
) -> FloatArray:
    """The centre (the plane's two coordinates, m) of the arc of ``radius`` (m; negative: the
    arc longer than half a circle) from ``start`` to ``end`` (the plane's coordinates, m).
    A radius short of half the chord by up to ``tolerance`` (m) is taken as half of it."""
    chord = end - start
    d = float(np.hypot(*chord))
    if d <= SAME_POINT:
        raise ArcError("the end is the start: the R form cannot draw a full circle (give the "
                       "centre with I J K)")
    half = d / 2.0
    if abs(radius) < half - tolerance:
        raise ArcError(f"R = {_mm(radius)} mm is shorter than half the chord, {_mm(half)} mm: "
                       "no arc of that radius joins the start and the end")  # fmt: skip
    h = math.sqrt(max(radius * radius - half * half, 0.0))
    left = np.array([-chord[1], chord[0]]) / d  # the travel direction turned +90°
    # a short counter-clockwise arc turns about a centre on its left; clockwise or long: right
    side = 1.0 if (radius > 0) != clockwise else -1.0
    return start + chord / 2.0 + side * h * left


def sweep(start: FloatArray, end: FloatArray, centre: FloatArray, clockwise: bool,
          turns: int) -> float:  # fmt: skip
    """The angle (rad; negative clockwise) from ``start`` to ``end`` about ``centre`` (the
    plane's coordinates, m), the way the arc turns: an end at the start is a full circle;
    ``turns`` (≥ 1) full circles in all, counting the last, partial one."""
    a0 = math.atan2(start[1] - centre[1], start[0] - centre[0])
    a1 = math.atan2(end[1] - centre[1], end[0] - centre[0])
    if float(np.hypot(*(end - start))) <= SAME_POINT:
        angle = 2.0 * math.pi
    else:
        angle = (a0 - a1 if clockwise else a1 - a0) % (2.0 * math.pi)
    angle += 2.0 * math.pi * (turns - 1)
    return -angle if clockwise else angle


def chords(radius: float, angle: float, tolerance: float) -> int:
    """How many equal chords keep an arc of ``radius`` (m) turning ``angle`` (rad) within
    ``tolerance`` (m): each chord's sagitta r (1 − cos(φ/2)) ≤ tolerance."""
    phi = 2.0 * math.acos(max(1.0 - tolerance / radius, 0.0))  # the widest chord's angle
    return max(1, math.ceil(abs(angle) / phi - 1e-9))


def arc_points(
    start: FloatArray, end: FloatArray, centre: FloatArray, plane: int, clockwise: bool,
    turns: int, tolerance: float,
) -> list[FloatArray]:  # fmt: skip
    """The chords' ends (poses: x, y, z m, roll, pitch, yaw rad), the last exactly ``end``,
    of the arc from the pose ``start`` about ``centre`` (the plane's two coordinates, m).
    The radius goes from the start's to the end's in proportion to the angle (the reader
    allows them to differ by ``tolerance`` at most)."""
    a, b = PLANES[plane]
    s, e = start[[a, b]], end[[a, b]]
    r0, r1 = float(np.hypot(*(s - centre))), float(np.hypot(*(e - centre)))
    angle = sweep(s, e, centre, clockwise, turns)
    n = chords(max(r0, r1), angle, tolerance)
    a0 = math.atan2(s[1] - centre[1], s[0] - centre[0])
    out = []
    for k in range(1, n):
        t = k / n
        p = start + (end - start) * t  # the coordinates off the plane, in proportion
        r, theta = r0 + (r1 - r0) * t, a0 + angle * t
        p[a], p[b] = centre[0] + r * math.cos(theta), centre[1] + r * math.sin(theta)
        out.append(p)
    out.append(np.array(end, dtype=float))
    return out


def _mm(x: float) -> str:
    """A length (m) in mm, as the messages give it."""
    return f"{x * 1e3:.4g}"
