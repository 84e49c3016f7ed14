"""Path files (motion/path_file.py) and their plans (motion/path_plan.py): what is read, what
is refused with its line and column, what the plan guarantees (limits, blends, times)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cdprctl.cli import main
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.path_file import parse_path
from cdprctl.motion.path_plan import CHECK_SPACING, PathRejectedError, plan_path
from cdprctl.motion.trajectory import Trajectory, pose_coordinates
from cdprctl.motion.waypoints import PathFileError
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[2]
START = np.array([1.5, 0.35, 0.59, 0.0, 0.0, 0.0])


def refusal(text: str) -> str:
    """What ``parse_path`` says refusing ``text`` from START: one line (checked here)."""
    with pytest.raises(PathFileError) as e:
        parse_path(text, START)
    said = str(e.value)
    assert "\n" not in said, said
    return said


@pytest.fixture(scope="module")
def rowc():
    return load_robot(ROOT / "config" / "rowc.toml")


def test_gcode_units_modes_and_comments():
    text = """%
N10 G21 G90 (mm) ; a comment
G0 X1000 Z500
G4 P1.5
G91 G1 Y10 F600 A5.7296
G20 G1 X1 F60
G90 G64 G1 X1200 Z600
G1 X1300
G61 G1 X1400
M30
G1 X9999
"""
    w = parse_path(text, START)
    assert len(w) == 6  # nothing after M30
    assert w[0].pose[:3] == pytest.approx((1.0, 0.35, 0.5)) and w[0].speed is None
    assert w[0].dwell == 1.5 and not w[0].blend
    assert w[1].pose[1] == pytest.approx(0.36) and w[1].speed == pytest.approx(0.01)
    assert w[1].pose[3] == pytest.approx(0.1, abs=1e-6)  # A: degrees → roll (rad)
    assert w[2].pose[0] == pytest.approx(1.0254) and w[2].speed == pytest.approx(0.0254)
    assert w[3].pose[:3] == pytest.approx((0.0254 * 1200, 0.36, 0.0254 * 600))  # still G20
    assert w[3].blend and w[4].pose[0] == pytest.approx(0.0254 * 1300) and w[4].blend
    assert not w[5].blend and w[5].where == "line 9"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("G0 X0 Y0\nG2 X2 Y1 I1 J0 F100\n", "line 2: G2: the radius at the start, 1.0000 mm, "
         "and at the end, 1.4142 mm, differ by 0.4142 mm, more than [paths] arc_tolerance = "
         "0.1 mm"),
        ("G1 X1 F100 Q5\n", "line 1, column 12: word Q5 is not supported"),
        ("G1 X10\n", "line 1: G1 needs a feed rate F"),
        ("G0 X1 X2\n", "line 1, column 7: X given twice"),
        ("X10\n", "line 1: axis words need a motion mode: G0, G1, G2 or G3"),
        ("G4\n", "line 1: G4 needs P"),
        ("G1 X1 F-5\n", "line 1, column 7: F-5 must be > 0"),
        ("G0 X1 (open\n", "line 1, column 7: comment not closed"),
        ("G0 X1 M0\n", "line 1, column 7: M0 is refused: a pause for the operator"),
        ("G0 X1 $\n", "line 1, column 7: '$' is not a G-code word"),
        ("G21\n", "no motion"),
        ("x, y, z, speed\n1, 2\n", "line 2: 2 values for 4 columns"),
        ("x, y, z\n1, 0.3, abc\n", "line 2, column 3: z = 'abc' must be a finite number (m)"),
        ("x, y, w\n", "line 1, column 3: 'w' is not a column"),
        ("x, y, z, speed, time\n", "give speed or time, not both"),
        ("x, y, z, time\n1, 2, 3, 2\n1, 2, 3, 1\n", "line 3: time = 1 s must be later"),
        ("x, y, z, speed\n1, 2, 3, 0\n", "line 2: speed = 0 m/s must be > 0"),
        ("x, y, z, blend\n1, 2, 3, 2\n", "line 2: blend = 2 must be 0 or 1"),
        ("x, y, z\n", "a header but no waypoint"),
        ("G0 X1 (a (b) c)\n", "line 1, column 10: nested comment"),
        ("G0 X1 a)\n", "line 1, column 8: ')' without '('"),
        ("G1.5 X1\n", "line 1, column 1: G1.5 is not supported"),
        ("G19 X1\n", "line 1: axis words need a motion mode"),
        ("G0 X1 G1 Y2 F10\n", "line 1, column 7: two motions in a block"),
        ("G4 P1 X3\n", "line 1: G4 takes no axis words"),
        ("G0 X1 P2\n", "line 1, column 7: P belongs to G4"),
        ("G4 P3600.5\n", "line 1, column 4: P3600.5 must be a dwell in [0, 3600] s"),
        ("G4 P-0.5\n", "line 1, column 4: P-0.5 must be a dwell"),
        ("G0\n", "the G-code has no motion (G0 G1 G2 G3 with axis words)"),
        ("G1 X1 F0\n", "line 1, column 7: F0 must be > 0 (mm/min)"),
        ("G20 G1 X1 F0\n", "line 1, column 11: F0 must be > 0 (in/min)"),
        ("G0 X1 M98\n", "line 1, column 7: M98 is not supported"),
        ("G1 X1 F100 D5\n", "line 1, column 12: word D5 is not supported"),
        ("G0 X1\n$\n", "line 2, column 1: '$' is not a G-code word"),
        ("G0 X1 $ Y2\n", "line 1, column 7: '$' is not a G-code word"),
        ("((a)) G0 X1\n", "line 1, column 2: nested comment"),
        ("(open\n", "line 1, column 1: comment not closed"),
        ("x, y, z\n1, 2, 3, 4\n", "line 2: 4 values for 3 columns"),
        ("G1 X1 F100 E5\n", "line 1, column 12: word E5 is not supported"),
        ("x, y, z, dwell\n1, 2, 3, 3600.5\n", "line 2: dwell = 3600.5 s must be in [0, 3600] s"),
        ("x, y, z, dwell\n1, 2, 3, -1\n", "line 2: dwell = -1 s must be in [0, 3600] s"),
        ("x, y, z, blend\n1, 2, 3, 0.5\n", "line 2: blend = 0.5 must be 0 or 1"),
        ("x, y, z, speed\n1, 2, 3, -0.1\n", "line 2: speed = -0.1 m/s must be > 0"),
        ("x, y, z, time\n1, 2, 3, 0\n", "line 2: time = 0 s must be later than the previous "
         "waypoint's 0 s"),
        ("x, x, z\n", "column 'x' appears twice"),
        ("x, z, roll\n", "the header needs x, y, z (missing: y)"),
    ],
)
def test_refusals_name_line_and_column(text, message):
    assert message in refusal(text)


def test_what_the_files_say_is_what_the_waypoints_are():
    """At the edges of each rule: the bounds themselves accepted, the default unit (mm), the
    modes and their words read as the G-code standard says, comments skipped (CSV '#', G-code
    '(…)' and ';'), a dwell before any motion held at the start."""
    w = parse_path("# a comment first\nx, y, z, dwell, blend\n# and between\n"
                   "1, 2, 3, 3600, 1\n4, 5, 6, 0, 0\n", START)  # fmt: skip
    assert [x.dwell for x in w] == [3600.0, 0.0] and [x.blend for x in w] == [True, False]
    assert w[0].pose == (1.0, 2.0, 3.0, *START[3:]) and w[0].time is None
    w = parse_path("x, y, z, time\n1, 2, 3, 0.5\n1, 2, 4, 1.5\n", START)
    assert [x.time for x in w] == [0.5, 1.5]
    w = parse_path("G4 P0\nG4 P3600\nG0 X100 (mm: the default) ; and more\nG91 G0 X-50\n"
                   "G0 Y10 Z5\nG90 G0 X7\n", START)  # fmt: skip
    assert w[0].pose == tuple(START) and w[0].dwell == 3600.0  # held at the start
    assert w[1].pose[0] == pytest.approx(0.1) and w[1].speed is None and not w[1].blend
    assert w[2].pose[0] == pytest.approx(0.05)  # relative
    assert w[3].pose[1:3] == pytest.approx((START[1] + 0.01, START[2] + 0.005))  # still G91
    assert w[4].pose[0] == pytest.approx(0.007)  # absolute again
    w = parse_path("G1 X10 F6000\nG4 P2\nG1 X20\n", START)
    assert w[0].dwell == 2.0 and w[0].speed == pytest.approx(0.1) and w[1].dwell == 0.0
    assert w[1].speed == pytest.approx(0.1)  # the feed is modal
    w = parse_path("G21 G1 X10 F60 M2\nG1 X20\n", START)
    assert len(w) == 1  # M2 ends the program too
    w = parse_path("(first a comment) G1 X10 F6000\nG1 X20\nG4 P2\nG20 G0 X1\nG21 G0 X1000\n",
                   START)  # fmt: skip
    assert [x.dwell for x in w] == [0.0, 2.0, 0.0, 0.0]  # the dwell on the motion before it
    assert [x.pose[0] for x in w[:2]] == pytest.approx([0.01, 0.02])  # and nothing else of it
    assert w[2].pose[0] == pytest.approx(0.0254) and w[3].pose[0] == pytest.approx(1.0)
    assert w[2].speed is None and w[1].speed is not None  # G0 is rapid: no feed, set or not
    w = parse_path("N5 G0 X1 B5.72958 C-5.72958 A2.86479 ; a ( comment\n"
                   "(a;b) G1 X2 F0.5 (c;d)\n", START)  # fmt: skip
    assert w[0].pose[:3] == pytest.approx((0.001, START[1], START[2]))
    assert w[0].pose[3:] == pytest.approx((0.05, 0.1, -0.1), abs=1e-6)  # degrees → rad
    assert w[1].speed == pytest.approx(0.5e-3 / 60.0)
    w = parse_path("G4 P1\nG0 X100\n", START)
    assert not w[0].blend and not w[1].blend  # the dwell at the start is no blend
    assert not parse_path("x, y, z\n1, 2, 3\n", START)[0].blend  # without the column: 0


def play(model, plan):
    """The plan through a fresh trajectory at the loop's period: positions, velocities,
    accelerations, jerks (finite differences) and the times each segment ended."""
    tr = Trajectory(model, model.control.period)
    tr.reset(plan.start)
    p, v, a, ends = [], [], [], []
    for s in plan.segments:
        tr.set_segment(s.target, s.velocity, s.max_velocity, s.max_acceleration,
                       s.minimum_duration)  # fmt: skip
        while not tr.finished:
            tr.update(model.control.period)
            p.append(tr.position.copy())
            v.append(tr.velocity.copy())
            a.append(tr.acceleration.copy())
        ends.append(len(p) * model.control.period)
    return np.array(p), np.array(v), np.array(a), ends


def test_blended_circle_keeps_the_limits_and_saves_time(rowc):
    """rowc_circle.ngc with G64: passed moving (faster than with exact stops), every
    coordinate within its velocity, acceleration and jerk limits (jerk by finite differences
    of ruckig's accelerations), close to the chords."""
    text = (ROOT / "paths" / "rowc_circle.ngc").read_text()
    start = pose_coordinates(rowc, START[:3], rowc.home.rotation)
    blended = plan_path(rowc, parse_path(text, START), start, rowc.control.period)
    exact = plan_path(rowc, parse_path(text.replace("G64", "G61"), START), start,
                      rowc.control.period)  # fmt: skip
    assert blended.duration < 0.75 * exact.duration
    c = rowc.control
    p, v, a, ends = play(rowc, blended)
    dt = c.period
    assert np.abs(v[:, :3]).max() <= 0.15 + 1e-9  # F9000 mm/min, per axis where it blends
    assert np.abs(a[:, :3]).max() <= c.max_acceleration + 1e-9
    jerk = np.diff(a[:, :3], axis=0) / dt
    assert np.abs(jerk).max() <= c.max_jerk * (1 + 1e-6)
    # the rounded corners stay near the circle (radius 0.1 m about (1.5, 0.59) in x-z)
    circle = p[round(ends[0] / dt):round(ends[-2] / dt)]  # the 24 chords
    r = np.hypot(circle[:, 0] - 1.5, circle[:, 2] - 0.59)
    assert np.abs(r - 0.1).max() < 5e-3  # measured 4.2 mm (the chords alone: 0.86 mm)


class LimitsWithABand(SoftLimits):
    """rowc's soft limits plus a slab ``x ∈ [x0, x0 + width]`` (m) where the margin is
    −1 N: a region narrower than any spacing a coarse check could get away with."""

    def __init__(self, model, x0: float, width: float):
        super().__init__(model)
        self.x0, self.width = x0, width

    def check(self, coords, acceleration=None, floor=None, **clearance):
        margin, ok = super().check(coords, acceleration, floor, **clearance)
        x = np.asarray(coords, dtype=float).reshape(-1, 6)[:, 0]
        inside = (x >= self.x0) & (x <= self.x0 + self.width)
        return np.where(inside, -1.0, margin), ok & ~inside


def test_the_check_samples_densely_enough_to_find_a_narrow_band(rowc):
    """Both waypoints hold and the line between them crosses a 3 mm band that does not:
    every sample of the plan is within CHECK_SPACING (2 mm) of the next, so the band is hit
    wherever it lies — here at several offsets along a 0.4 m segment and a blended circle."""
    start = pose_coordinates(rowc, START[:3], rowc.home.rotation)
    text = "x, y, z\n1.9, 0.35, 0.59\n"
    clear = plan_path(rowc, parse_path(text, START), start, rowc.control.period)
    assert clear.spacing <= CHECK_SPACING
    assert clear.samples >= 0.4 / CHECK_SPACING
    for x0 in (1.5123, 1.6401, 1.7777, 1.8953):
        with pytest.raises(PathRejectedError, match=r"line 2 \(segment 1\): at t = .* tension "
                           r"margin is -1\.00 N"):
            plan_path(rowc, parse_path(text, START), start, rowc.control.period,
                      limits=LimitsWithABand(rowc, x0, 0.003))  # fmt: skip
    circle = (ROOT / "paths" / "rowc_circle.ngc").read_text()
    plan = plan_path(rowc, parse_path(circle, START), start, rowc.control.period)
    assert plan.spacing <= CHECK_SPACING
    p, _, _, _ = play(rowc, plan)  # the path as the loop plays it, every period
    steps = np.linalg.norm(np.diff(p[:, :3], axis=0), axis=1)
    assert plan.samples >= steps.sum() / CHECK_SPACING  # as many samples as 2 mm apart needs


def test_timed_rows_are_reached_on_time_or_refused(rowc):
    start = pose_coordinates(rowc, START[:3], rowc.home.rotation)
    text = "x, y, z, time\n1.6, 0.35, 0.59, 2.0\n1.6, 0.35, 0.64, 3.5\n"
    plan = plan_path(rowc, parse_path(text, START), start, rowc.control.period)
    _, _, _, ends = play(rowc, plan)
    assert ends == pytest.approx([2.0, 3.5], abs=2 * rowc.control.period)
    with pytest.raises(PathRejectedError, match=r"line 3: its time cannot be met: the "
                       r"segment needs .* s at the velocity and acceleration limits, 0.100"):
        plan_path(rowc, parse_path("x, y, z, time\n1.6, 0.35, 0.59, 2\n1.9, 0.35, 0.59, 2.1\n",
                                   START), start, rowc.control.period)  # fmt: skip
    with pytest.raises(PathRejectedError, match=r"speed 0\.5 m/s exceeds the configured"):
        plan_path(rowc, parse_path("x, y, z, speed\n1.6, 0.35, 0.59, 0.5\n", START), start,
                  rowc.control.period)  # fmt: skip


def test_run_path_rejects_before_enabling(tmp_path, capsys):
    bad = tmp_path / "bad.ngc"
    bad.write_text("G21 G90\nG0 X1500 Z590\nG1 X2900 F6000\n")
    rc = main(["run", "--config", str(ROOT / "config" / "rowc.toml"), "--sim", "--no-realtime",
               "--status", "0", "--path", str(bad)])  # fmt: skip
    out = capsys.readouterr()
    assert rc == 2
    assert (f"cdprctl run: path {bad} rejected: line 3 (the end of segment 2): waypoint "
            "[2.9, 0.35, 0.59, 0.0, 0.0, 0.0]: x = 2.9000 m is outside the workspace box "
            "[0.5, 2.5] m") in out.err
    assert "enabling" not in out.out
    assert math.isfinite(1.0)


def test_a_csv_row_of_units_converts_its_columns():
    """A row of units under the header: mm, cm-free lengths, degrees, speeds per minute, ms;
    each value in SI exactly as the unit says (against the conversions written out here)."""
    text = ("# a wipe in millimetres\nx, y, z, roll, yaw, speed, dwell, blend\n"
            "mm, mm, mm, deg, deg, mm/min, ms, -\n1400, 350, 500, 90, -45, 6000, 250, 1\n"
            "1800, 350, 500, 0, 0, 6000, 0, 0\n")  # fmt: skip
    w = parse_path(text, START)
    assert w[0].pose == pytest.approx((1.4, 0.35, 0.5, math.pi / 2, 0.0, -math.pi / 4))
    assert w[0].speed == pytest.approx(0.1) and w[0].dwell == pytest.approx(0.25)
    assert w[0].blend and not w[1].blend and w[0].where == "line 4"
    inches = parse_path("x,y,z,speed\nin,in,in,in/s\n10,20,30,2\n", START)[0]
    assert inches.pose[:3] == pytest.approx((0.254, 0.508, 0.762)) and inches.speed == 0.0508
    timed = parse_path("x,y,z,time\nm,m,m,ms\n1,2,3,1500\n", START)[0]
    assert timed.time == pytest.approx(1.5)
    assert parse_path("x,y,z,pitch\nm, m, m, rad\n1,2,3,0.5\n", START)[0].pose[4] == 0.5


#: one of each unit word in SI, written out here from the units' definitions (1 in = 25.4 mm
#: exactly, 1° = π/180 rad, 1 min = 60 s), not read from path_file's table
SI_OF_ONE = {
    "x": {"m": 1.0, "mm": 0.001, "in": 0.0254},
    "roll": {"rad": 1.0, "deg": math.radians(1.0)},
    "speed": {"m/s": 1.0, "mm/s": 0.001, "mm/min": 0.001 / 60, "in/s": 0.0254,
              "in/min": 0.0254 / 60},
    "time": {"s": 1.0, "ms": 0.001},
    "dwell": {"s": 1.0, "ms": 0.001},
}  # fmt: skip
SI_OF_ONE |= {"y": SI_OF_ONE["x"], "z": SI_OF_ONE["x"], "pitch": SI_OF_ONE["roll"],
              "yaw": SI_OF_ONE["roll"]}  # fmt: skip


@pytest.mark.parametrize(
    "column, word", [(c, w) for c, units in SI_OF_ONE.items() for w in units]
)
def test_every_unit_word_is_its_si_value(column, word):
    """Each word of a unit row, in each column it belongs to: 7.5 of it is 7.5 × its SI value
    (a wrong factor in one cell of the table is wrong here, and only here)."""
    columns = ["x", "y", "z"] + [column] * (column not in ("x", "y", "z"))
    if column == "time":
        columns.append("blend")  # a timed row; blend keeps the row count the same
    units = [word if c == column else {"blend": "-"}.get(c, "m") for c in columns]
    values = ["7.5" if c == column else ("0" if c == "blend" else "1") for c in columns]
    w = parse_path(f"{','.join(columns)}\n{','.join(units)}\n{','.join(values)}\n", START)[0]
    got = {"x": w.pose[0], "y": w.pose[1], "z": w.pose[2], "roll": w.pose[3],
           "pitch": w.pose[4], "yaw": w.pose[5], "speed": w.speed, "time": w.time,
           "dwell": w.dwell}[column]  # fmt: skip
    assert got == pytest.approx(7.5 * SI_OF_ONE[column][word], rel=1e-12)


def test_blend_needs_no_unit_word_and_nothing_else_goes_without():
    """Blend is a 0/1 flag: its cell of the unit row may be empty (or ``-``); an empty cell
    under any other column is refused, naming it."""
    w = parse_path("x,y,z,blend\nm,m,m,\n1,2,3,1\n1,2,4,0\n", START)
    assert w[0].blend and not w[1].blend and w[0].pose[:3] == (1, 2, 3)
    mm = parse_path("x,y,z,blend\nmm,mm,mm,-\n1,2,3,1\n", START)[0]
    assert mm.pose[:3] == pytest.approx((0.001, 0.002, 0.003))
    for header, row, col in [("x,y,z", ",m,m", "column 1: '' is not a unit of x"),
                             ("x,y,z,roll", "m,m,m,", "column 4: '' is not a unit of roll"),
                             ("x,y,z,dwell", "m,m,m,", "column 4: '' is not a unit of dwell")]:
        with pytest.raises(PathFileError, match=f"line 2, {col}"):
            parse_path(f"{header}\n{row}\n1,2,3,0\n", START)


def test_units_for_a_csv_without_its_row():
    """``units``: the lengths and speeds (per s) of a CSV without a row of units; G-code and a
    CSV that has the row keep theirs."""
    w = parse_path("x,y,z,speed,roll\n1400,350,500,100,0.5\n", START, units="mm")[0]
    assert w.pose == pytest.approx((1.4, 0.35, 0.5, 0.5, 0.0, 0.0)) and w.speed == 0.1
    assert parse_path("x,y,z\nm,m,m\n1,2,3\n", START, units="mm")[0].pose[:3] == (1, 2, 3)
    g = parse_path("G21\nG1 X1400 Y350 Z500 F6000\n", START, units="in")[0]
    assert g.pose[:3] == pytest.approx((1.4, 0.35, 0.5))
    with pytest.raises(PathFileError, match="units = 'cm': must be one of m, mm, in"):
        parse_path("x,y,z\n1,2,3\n", START, units="cm")


@pytest.mark.parametrize(
    "text, words",
    [
        ("x,y,z\nmm,mm,furlong\n1,2,3\n", "line 2, column 3: 'furlong' is not a unit of z "
                                          "(one of: m, mm, in)"),
        ("x,y,roll,z\nmm,mm,mm,mm\n1,2,3,4\n", "line 2, column 3: 'mm' is not a unit of roll"),
        ("x,y,z\n1,2,3\nmm,mm,mm\n", "line 3, column 1: x = 'mm' must be a finite number"),
        ("x,y,z\nnan,inf,1\n", "line 2, column 1: x = 'nan' must be a finite number"),
    ],
)  # fmt: skip
def test_a_wrong_unit_row_is_refused_by_line_and_column(text, words):
    assert words in refusal(text)


def test_path_check_plans_offline_and_hints_at_millimetres(tmp_path, capsys):
    """``cdprctl path check``: the plan of a path that holds (exit 0), a millimetre file read
    as metres refused with the hint (exit 2), the same with --units mm (exit 0), a bad
    --from (exit 2)."""
    cfg = str(ROOT / "config" / "rowc.toml")
    assert main(["path", "check", str(ROOT / "paths" / "rowc_wipe.csv"), "--config", cfg]) == 0
    out = capsys.readouterr().out
    assert "6 segments, 19.20 s" in out and "smallest tension margin" in out
    assert "ok: the path holds" in out
    mm = tmp_path / "mm.csv"
    mm.write_text("x,y,z\n1400,350,500\n1800,350,500\n")
    assert main(["path", "check", str(mm), "--config", cfg]) == 2
    err = capsys.readouterr().err
    assert "x = 1400.0000 m is outside the workspace box" in err
    assert "add a row of units under the header" in err and "--units mm" in err
    assert main(["path", "check", str(mm), "--config", cfg, "--units", "mm"]) == 0
    assert "2 segments" in capsys.readouterr().out
    assert main(["path", "check", str(mm), "--config", cfg, "--from", "1.5,0.35"]) == 2
    assert "--from = '1.5,0.35'" in capsys.readouterr().err
    # a start left of the origin is a pose, not an option argparse cannot find
    wipe = str(ROOT / "paths" / "rowc_wipe.csv")
    assert main(["path", "check", wipe, "--config", cfg, "--from", "-1.5,0.35,0.59"]) == 2
    err = capsys.readouterr().err
    # the start is refused as the start, not blamed on the file's first line with its units
    assert err.startswith("cdprctl path check: error: --from = '-1.5,0.35,0.59': x = -1.5000 m "
                          "is outside the workspace box [0.5, 2.5] m ([workspace] of ")  # fmt: skip
    assert "line" not in err and "millimetres" not in err and err.count("\n") == 1
    assert main(["path", "check", wipe, "--config", cfg, "--from", "1.5,0.35,0.59,0,0,0.5"]) == 2
    assert "the tilt 28.65° (0.5000 rad) from the home orientation exceeds" in (
        capsys.readouterr().err)


def test_run_takes_units_for_its_path(tmp_path, capsys):
    """``cdprctl run --path`` reads a CSV as ``--units`` says: a millimetre file without the
    option is refused before the drives are enabled, with the hint."""
    mm = tmp_path / "mm.csv"
    mm.write_text("x,y,z\n1400,350,500\n")
    rc = main(["run", "--config", str(ROOT / "config" / "rowc.toml"), "--sim", "--no-realtime",
               "--path", str(mm)])  # fmt: skip
    assert rc == 2
    assert "or give --units mm" in capsys.readouterr().err


@pytest.mark.parametrize("text, without", [
    ("", False),  # nothing: no CSV
    ("G1 X1 Y2 Z3\n", False),  # G-code: no CSV header
    ("x,y,z\n", True),  # a header alone: no row of units
    ("x,y,z\nm,m,m\n", False),  # the row of units, no waypoint yet
    ("x,y,z\nmm,mm,mm\n1,2,3\n", False),
    ("x,y,z\n1,2,3\n4,5,6\n", True),  # numbers under the header: the units are --units'
    ("# a comment\nx,y,z\n\n1,2,3\n", True),
])  # fmt: skip
def test_a_csv_without_a_row_of_units_is_told_apart(text, without):
    from cdprctl.motion.path_file import csv_without_units

    assert csv_without_units(text) is without


def test_a_blend_passes_no_faster_than_the_slower_segment_allows(rowc):
    """A fast row blended into a slow one: the waypoint is passed within the slow segment's
    speed (per axis: a blend turns from one line to the next), not at the fast one's."""
    start = pose_coordinates(rowc, START[:3], rowc.home.rotation)
    text = "x, y, z, speed, blend\n1.8, 0.35, 0.54, 0.15, 1\n1.9, 0.35, 0.44, 0.01, 0\n"
    plan = plan_path(rowc, parse_path(text, START), start, rowc.control.period)
    passing = np.abs(plan.segments[0].velocity[:3])
    assert passing.max() > 0.0  # it is passed moving
    assert passing.max() <= 0.01 * (1 + 1e-9)
    _, v, _, ends = play(rowc, plan)
    at = round(ends[0] / rowc.control.period) - 1
    assert np.abs(v[at, :3]).max() <= 0.01 * (1 + 1e-6)


def test_a_rejected_waypoint_is_named_to_the_tenth_of_a_millimetre(rowc):
    start = pose_coordinates(rowc, START[:3], rowc.home.rotation)
    with pytest.raises(PathRejectedError, match=r"line 2 \(the end of segment 1\): waypoint "
                       r"\[2\.6123, 0\.35, 0\.59, "):  # fmt: skip
        plan_path(rowc, parse_path("x, y, z\n2.61234, 0.35, 0.59\n", START), start,
                  rowc.control.period)  # fmt: skip


def test_run_path_is_planned_once_the_loop_serves_the_drives():
    """``--path``'s plan is made by the I/O thread at the first READY, the loop running and
    the drives served (planned during the start-up, a 105-segment program took 3 s and the
    started drives were lost on their heartbeats), before any enable; rejected, nothing else
    is sent."""
    from conftest import CONFIG

    from cdprctl.control.data import ControlData
    from cdprctl.control.states import State
    from cdprctl.daemon.scripts import PathScript

    model = load_robot(CONFIG / "rowc.toml")
    seen = []

    def planner(start):
        seen.append(start.copy())
        return (None, "a segment leaves the workspace") if len(seen) > 1 else ("plan", "")

    d = ControlData(model.n_cables, 0)
    d.state = State.INIT
    script = PathScript("p.ngc", "G1 X1", planner)
    assert script.step(d) is None and seen == []  # not before the start-up's end
    d.state = State.READY
    assert script.step(d) is None and len(seen) == 1 and script.plan == "plan"
    assert script.step(d).kind.value == "enable"
    bad = PathScript("q.ngc", "G1 X9", planner)
    assert bad.step(d) is None and bad.done and bad.rejected == "a segment leaves the workspace"
