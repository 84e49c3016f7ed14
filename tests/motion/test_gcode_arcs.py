"""G2/G3 arcs (motion/arcs.py, read by motion/gcode.py) against a reference written out here:
every chord's end on the circle, each chord's sagitta (r − the distance from the centre to the
chord's midpoint) within the tolerance, the end exact, the turning direction by the sign of
the 3D cross product about the plane's axis, the angle turned in all, a helix's linear axis
in proportion to the angle."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_path_files import START, refusal

from cdprctl.motion.path_file import parse_path
from cdprctl.motion.waypoints import PathFileError

#: the plane's G code → the axis it turns about (index, as in the pose) — the right-hand rule
NORMAL = {17: 2, 18: 1, 19: 0}


def arc(text: str, tol: float = 1e-4) -> np.ndarray:
    """The poses of every waypoint of ``text`` (m, rad), the start first."""
    w = parse_path(text, START, arc_tolerance=tol)
    return np.array([START, *[x.pose for x in w]])


def check_circle(p: np.ndarray, centre: np.ndarray, r: float, normal: int, tol: float,
                 ccw: bool) -> float:  # fmt: skip
    """The reference checks on the points ``p`` (the arc's, the start first) about
    ``centre`` (3D, m; its normal coordinate ignored); returns the angle turned (rad)."""
    d = p[:, :3] - centre
    d[:, normal] = 0.0  # in the plane
    assert np.abs(np.linalg.norm(d, axis=1) - r).max() < 1e-9  # on the circle
    mid = (d[1:] + d[:-1]) / 2.0
    sagitta = r - np.linalg.norm(mid, axis=1)
    assert sagitta.max() <= tol * (1 + 1e-9)
    cross = np.cross(d[:-1], d[1:])[:, normal]
    assert np.all(cross > 0) if ccw else np.all(cross < 0)
    turned = float(np.sum(np.arctan2(cross, np.einsum("ij,ij->i", d[:-1], d[1:]))))
    n = len(p) - 1
    if n > 1:  # one chord fewer would leave the tolerance: no more chords than needed
        assert r * (1 - math.cos(abs(turned) / (n - 1) / 2)) > tol
    return turned


@pytest.mark.parametrize("tol", [1e-5, 1e-4, 1e-3])
@pytest.mark.parametrize("code, ccw", [("G2", False), ("G3", True)])
def test_a_quarter_circle_in_the_xy_plane(code, ccw, tol):
    """From (1500, 350) about (1500, 370) (mm) to (1520, 370): counter-clockwise a quarter,
    clockwise three quarters."""
    p = arc(f"G21 G90 G17\nG0 X1500 Y350 Z590\n{code} X1520 Y370 I0 J20 F3000\n", tol)[1:]
    centre = np.array([1.5, 0.37, 0.0])
    turned = check_circle(p, centre, 0.02, 2, tol, ccw)
    # from below the centre to its right: a quarter counter-clockwise, three clockwise
    assert turned == pytest.approx(math.pi / 2 if ccw else -3 * math.pi / 2)
    assert tuple(p[-1]) == (*np.array([1520, 370, 590]) * 1e-3, 0.0, 0.0, 0.0)  # the end, exactly
    expected = math.ceil(abs(turned) / (2 * math.acos(1 - tol / 0.02)))
    assert len(p) - 1 == expected  # the fewest equal chords within the tolerance


@pytest.mark.parametrize("plane", [17, 18, 19])
@pytest.mark.parametrize("code", ["G2", "G3"])
def test_full_circles_in_each_plane_turn_the_right_way(plane, code):
    """The end at the start: a whole turn, the direction seen from the plane's axis' positive
    end (G3 counter-clockwise), with P2 two turns."""
    offset = {17: "I20", 18: "K20", 19: "J20"}[plane]
    for turns, extra in ((1, ""), (2, " P2")):
        p = arc(f"G21 G{plane}\nG0 X1500 Y350 Z590\n{code} {offset}{extra} F3000\n")[1:]
        centre = np.array([1.5, 0.35, 0.59])
        centre[{17: 0, 18: 2, 19: 1}[plane]] += 0.02
        turned = check_circle(p, centre, 0.02, NORMAL[plane], 1e-4, code == "G3")
        assert turned == pytest.approx((2 * math.pi if code == "G3" else -2 * math.pi) * turns)
        assert tuple(p[-1]) == (*np.array([1500, 350, 590]) * 1e-3, 0.0, 0.0, 0.0)  # exactly


def test_a_helix_moves_its_axis_in_proportion_to_the_angle():
    """G17 with Z: the xy projection on the circle, z from 600 to 580 mm, linear in the
    angle turned; roll (A) too."""
    p = arc("G21 G17\nG0 X1520 Y365 Z600\nG3 X1520 Y365 Z580 A10 I-20 J0 P2 F3000\n")[1:]
    centre = np.array([1.5, 0.365, 0.0])
    check_circle(p, centre, 0.02, 2, 1e-4, True)
    d = p[:, :3] - centre
    d[:, 2] = 0.0
    step = np.arctan2(np.cross(d[:-1], d[1:])[:, 2], np.einsum("ij,ij->i", d[:-1], d[1:]))
    angle = np.concatenate([[0.0], np.cumsum(step)])
    np.testing.assert_allclose(p[:, 2], 0.6 - 0.02 * angle / (4 * math.pi), atol=1e-12)
    np.testing.assert_allclose(p[:, 3], math.radians(10) * angle / (4 * math.pi), atol=1e-12)


@pytest.mark.parametrize("code, r, ccw, long", [("G2", 20, False, False), ("G2", -20, False, True),
                                                ("G3", 20, True, False), ("G3", -20, True, True)])
def test_the_r_form_takes_the_short_arc_or_with_r_negative_the_long_one(code, r, ccw, long):
    """From (1500, 350) to (1520, 370) (mm) with |R| 20: the centre 20 mm from both ends; a
    quarter (R > 0) or three quarters (R < 0), the way the code turns."""
    p = arc(f"G21 G17\nG0 X1500 Y350 Z590\n{code} X1520 Y370 R{r} F3000\n")[1:]
    candidates = [np.array([1.5, 0.37, 0.0]), np.array([1.52, 0.35, 0.0])]
    for c in candidates:
        d = p[:, :2] - c[:2]
        if np.abs(np.linalg.norm(d, axis=1) - 0.02).max() < 1e-9:
            turned = check_circle(p, c, 0.02, 2, 1e-4, ccw)
            break
    else:
        raise AssertionError("no chord end-set on a circle of radius 20 mm through both ends")
    assert abs(turned) == pytest.approx(3 * math.pi / 2 if long else math.pi / 2)


def test_the_xz_plane_takes_k_and_i_and_g90_1_absolute_centres():
    """G18: the centre's offsets K (z) and I (x); G90.1: the centre's absolute coordinates
    (the same arc), G91.1 back to offsets."""
    rel = arc("G21 G18\nG0 X1500 Y350 Z590\nG3 X1550 Z640 K50 I0 F3000\n")
    absolute = arc("G21 G18 G90.1\nG0 X1500 Y350 Z590\nG3 X1550 Z640 K640 I1500 F3000\n")
    np.testing.assert_array_equal(rel, absolute)
    check_circle(rel[1:], np.array([1.5, 0.0, 0.64]), 0.05, 1, 1e-4, True)
    back = arc("G21 G18 G90.1\nG91.1\nG0 X1500 Y350 Z590\nG3 X1550 Z640 K50 I0 F3000\n")
    np.testing.assert_array_equal(rel, back)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("G17 G2 X1510 Y360 I5 J0 F100\n", "line 1: G2: the radius at the start, 5.0000 mm, and "
         "at the end, 11.1803 mm, differ by 6.1803 mm"),
        ("G0 X0 Y0\nG2 X10.3 I5 J0 F100\n", "line 2: G2: the radius at the start, 5.0000 mm, "
         "and at the end, 5.3000 mm, differ by 0.3000 mm, more than [paths] arc_tolerance = "
         "0.1 mm"),
        ("G0 X0 Y0\nG3 X10 I5 J0 K3 F100\n", "line 2, column 14: K is no centre offset in the "
         "G17 plane (its offsets: I J)"),
        ("G0 X0 Y0\nG2 X10 R2 F100\n", "line 2, column 8: G2 R2: R = 2 mm is shorter than half "
         "the chord, 5 mm"),
        ("G0 X0 Y0\nG2 X0 Y0 R5 F100\n", "line 2, column 10: G2 R5: the end is the start: the R "
         "form cannot draw a full circle"),
        ("G0 X0 Y0\nG2 X10 I5 R5 F100\n", "line 2, column 11: G2: give the centre (I J) or the "
         "radius R, not both"),
        ("G0 X0 Y0\nG2 X10 F100\n", "line 2: G2 needs its centre, I J from the start (G91.1), "
         "or its radius R"),
        ("G0 X0 Y0\nG90.1 G2 X10 I5 F100\n", "line 2: G2 needs its centre, I J both, absolute "
         "(G90.1), or its radius R"),
        ("G0 X0 Y0\nG2 X10 I0 J0 F100\n", "line 2: G2: the centre is the start (radius 0)"),
        ("G0 X0 Y0\nG2 I5 P1.5 F100\n", "line 2, column 7: P1.5 must be a whole number of turns"),
        ("G0 X0 Y0\nG2 I5 P0 F100\n", "line 2, column 7: P0 must be a whole number of turns, 1 "
         "or more"),
        ("G0 X0 Y0\nG2 I5000 P100 F100\n", "line 2: G2 needs 49673 chords within [paths] "
         "arc_tolerance = 0.1 mm: more than 10000"),
        ("G0 X0 Y0\nG1 X10 I5 F100\n", "line 2, column 8: I5 belongs to G2/G3"),
        ("G0 X0 Y0\nG2 X10 I5\n", "line 2: G2 needs a feed rate F"),
    ],
)
def test_inconsistent_arcs_are_refused_in_one_line(text, message):
    assert message in refusal(text)


def test_radii_within_the_tolerance_are_taken_and_the_end_is_exact():
    """Start and end radii 0.05 mm apart (a CAM file's rounding, less than 0.1 mm): taken, the
    radius going from one to the other, the end as written."""
    p = arc("G21 G17\nG0 X1500 Y350 Z590\nG2 X1520.05 Y370 I0 J20 F3000\n")
    assert tuple(p[-1][:3]) == tuple(np.array([1520.05, 370, 590]) * 1e-3)
    r = np.linalg.norm(p[:, :2] - [1.5, 0.37], axis=1)
    assert r[0] == pytest.approx(0.02) and r[-1] == pytest.approx(0.02005)
    assert np.all(np.diff(r) >= -1e-12)
    with pytest.raises(PathFileError, match=r"differ by 0\.1500 mm"):
        arc("G21 G17\nG0 X1500 Y350 Z590\nG2 X1520.15 Y370 I0 J20 F3000\n")
