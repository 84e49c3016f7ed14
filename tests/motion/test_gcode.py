"""G-code as CAM programs and slicers write it (motion/gcode.py): modal words, the words taken
and ignored or refused one by one, ``[paths] arc_tolerance``, the hint for a file in metres,
and files in a CAM post's and a slicer's style planned, checked and played."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_path_files import START, refusal

from cdprctl.cli import main
from cdprctl.model import ConfigError
from cdprctl.motion.path_file import parse_path
from cdprctl.motion.path_plan import plan_text, units_hint
from cdprctl.motion.trajectory import pose_coordinates
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
CAM_FILES = ["cam_mill_xy.ngc", "cam_facade_xz.ngc", "slicer_style.gcode"]


@pytest.fixture(scope="module")
def rowc():
    return load_robot(ROOT / "config" / "rowc.toml")


def poses(text: str) -> list[tuple]:
    return [(w.pose, w.speed, w.blend, w.dwell) for w in parse_path(text, START)]


def test_modal_lines_are_the_explicit_ones():
    """Axis words alone continue the last motion (G0, G1, G2, G3), at the last feed, in the
    last units, distances, plane and blending: the same waypoints as every word written out."""
    modal = ("G21 G90 G18\nG0 X1400 Z500\nZ520\nG1 X1450 F3000\nX1500 Z540\nG64\n"
             "G3 X1550 Z590 K50 I0\nX1600 Z640 K50 I0\nG91 G1 X10\nZ-10\nG61 G90 G0 X1500\n")
    explicit = ("G21 G90 G18\nG0 X1400 Z500\nG0 Z520\nG1 X1450 F3000\nG1 X1500 Z540 F3000\n"
                "G64\nG18 G3 X1550 Z590 K50 I0 F3000\nG3 X1600 Z640 K50 I0 F3000\n"
                "G91 G1 X10 F3000\nG91 G1 Z-10 F3000\nG61 G90 G0 X1500\n")  # fmt: skip
    assert poses(modal) == poses(explicit)
    w = parse_path(modal, START)
    assert w[1].pose[2] == pytest.approx(0.52) and w[1].speed is None  # still G0
    assert w[3].speed == pytest.approx(0.05)  # still F3000 mm/min


def test_modes_apply_before_the_blocks_motion_whatever_the_order():
    assert poses("G1 X1400 F60 G20\n") == poses("G20 G1 X1400 F60\n")
    assert poses("X1 Y2 G0 G91\n") == poses("G91 G0 X1 Y2\n")


@pytest.mark.parametrize(
    "header",
    ["G17 G54 G40 G49 G80 G90", "G90 G94 G17 G91.1", "T1 M6", "S5000 M3", "M4", "M5", "M7",
     "M8", "M9", "M1", "N100 G40", "%", "(a comment) ; and another", "G49 G40 G54 G94 G80"],
)  # fmt: skip
def test_header_words_that_cannot_move_the_robot_are_taken_and_ignored(header):
    body = "G21\nG0 X1400 Y350 Z500\nG1 X1500 F3000\n"
    assert poses(f"{header}\n{body}") == poses(body)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("G28 G91 Z0\n", "line 1, column 1: G28 is refused: it goes to a stored home position"),
        ("G30\n", "line 1, column 1: G30 is refused"),
        ("G0 X1\nG41 D1\n", "line 2, column 1: G41 is refused: cutter compensation would "
         "offset the path"),
        ("G42\n", "line 1, column 1: G42 is refused"),
        ("G43 H1\n", "line 1, column 1: G43 is refused: a tool length offset would shift z"),
        ("G53 G0 Z0\n", "line 1, column 1: G53 is refused: machine coordinates"),
        ("G55\n", "line 1, column 1: G55 is refused: another work offset; only G54"),
        ("G59\n", "line 1, column 1: G59 is refused"),
        ("G81 X1 Z-2 R1\n", "line 1, column 1: G81 is refused: a canned cycle"),
        ("G89\n", "line 1, column 1: G89 is refused: a canned cycle"),
        ("G92 X0\n", "line 1, column 1: G92 is refused: it shifts the coordinates"),
        ("G10 L2 P1\n", "line 1, column 1: G10 is refused: it sets offsets"),
        ("G93\n", "line 1, column 1: G93 is refused: inverse-time feed"),
        ("G95\n", "line 1, column 1: G95 is refused: feed per revolution"),
        ("G0 X1 M0\n", "line 1, column 7: M0 is refused: a pause for the operator"),
        ("M3 M104 S200\n", "line 1, column 4: M104 is not supported (taken: M2 M30 end"),
        ("G1 X1 E0.5 F100\n", "line 1, column 7: word E0.5 is not supported (an extruder's "
         "axis; the robot has no extruder)"),
        ("O1001\n", "line 1, column 1: word O1001 is not supported"),
        ("G20 G21\n", "line 1, column 5: G21 and G20 in one block: both set the units"),
        ("G17 G18\n", "line 1, column 5: G18 and G17 in one block: both set the plane"),
        ("G90 G91\n", "line 1, column 5: G91 and G90 in one block: both set the distance"),
        ("G61 G64\n", "line 1, column 5: G64 and G61 in one block: both set the path control"),
        ("G90.1 G91.1\n", "line 1, column 7: G91.1 and G90.1 in one block: both set the arc"),
        ("G0 X1 G80\n", "line 1, column 7: two motions in a block"),
        ("G80 X1\n", "line 1: axis words need a motion mode: G0, G1, G2 or G3 on this line or "
         "one before (none since the start or G80)"),
        ("G0 X1\nG80\nX2\n", "line 3: axis words need a motion mode"),
        ("G1 X1 F10\nG64 P0.05\n", "line 2, column 5: P belongs to G4 (dwell) or G2/G3 (turns)"),
        ("G4 S1\n", "line 1: G4 needs P, the dwell in seconds"),
        ("G61.1\n", "line 1, column 1: G61.1 is not supported (supported: G0 G1 G2 G3 G4"),
        ("F100 F200\n", "line 1, column 6: F given twice"),
        ("G0 X1 R2\n", "line 1, column 7: R2 belongs to G2/G3"),
    ],
)
def test_words_that_would_change_the_path_are_refused_in_one_line(text, message):
    assert message in refusal(text)


def test_g0_or_g1_alone_sets_the_motion_and_a_second_percent_ends_the_program():
    assert poses("G1 F3000\nX1400\n") == poses("G1 X1400 F3000\n")
    assert poses("%\nG0 X1400\n%\nG0 X9999\n") == poses("G0 X1400\n")
    assert poses("G0 X1400\nM30\nG0 X9999\n") == poses("G0 X1400\n")


def test_arc_tolerance_is_read_from_the_robot_file_and_checked(tmp_path, rowc):
    assert rowc.paths.arc_tolerance == 1e-4  # the default
    base = (ROOT / "config" / "rowc.toml").read_text()
    for value, ok in (("0.0005", True), ("1e-5", True), ("0.01", True), ("0.0", False),
                      ("9e-6", False), ("0.0101", False), ('"0.1 mm"', False)):  # fmt: skip
        f = tmp_path / "r.toml"
        f.write_text(f"{base}\n[paths]\narc_tolerance = {value}\n")
        if ok:
            assert load_robot(f).paths.arc_tolerance == float(value)
            continue
        with pytest.raises(ConfigError) as e:
            load_robot(f)
        said = str(e.value)
        if value.startswith('"'):
            assert "paths.arc_tolerance = '0.1 mm' must be a number in m" in said
        else:
            assert (f"paths.arc_tolerance = {float(value):g} m must be in [1e-05, 0.01] m "
                    "(0.01 mm to 10 mm: the largest distance between an arc and its chords)"
                    ) in said  # fmt: skip
    f.write_text(f"{base}\n[paths]\narc_tol = 0.001\n")
    with pytest.raises(ConfigError, match=r"paths.arc_tol is not a known key \(did you mean "
                       "arc_tolerance"):  # fmt: skip
        load_robot(f)


def test_the_plan_takes_the_robots_arc_tolerance(tmp_path, rowc):
    """A coarser ``[paths] arc_tolerance``: fewer chords for the same file."""
    base = (ROOT / "config" / "rowc.toml").read_text()
    f = tmp_path / "coarse.toml"
    f.write_text(f"{base}\n[paths]\narc_tolerance = 0.002\n")
    coarse = load_robot(f)
    text = "G21 G18\nG0 X1400 Z590\nG2 X1600 Z590 R100 F6000\n"
    start = pose_coordinates(rowc, START[:3], rowc.home.rotation)
    fine = plan_text(rowc, text, start, rowc.control.period)
    rough = plan_text(coarse, text, start, coarse.control.period)
    for plan, tol in ((fine, 1e-4), (rough, 2e-3)):  # half a circle: ceil(π / φ_max) chords
        assert len(plan.segments) == 1 + math.ceil(math.pi / (2 * math.acos(1 - tol / 0.1)))
    assert len(rough.segments) < len(fine.segments)


def test_a_gcode_file_in_metres_gets_the_hint(tmp_path, capsys):
    """No G20/G21 and every X Y Z under 5: metres read as mm; refused outside the box with the
    hint. With G21, or with numbers in mm, no hint."""
    metres = "G90\nG0 X1.5 Y0.35 Z0.6\nG1 X1.6 F600\n"
    why = "x = 0.0015 m is outside the workspace box [0.5, 2.5] m"
    assert "a file in metres? G-code's lengths are mm unless G20" in units_hint(metres, "m", why)
    assert units_hint(f"%\n{metres}%\n", "m", why) != ""  # a program between % lines
    assert units_hint(metres, "mm", why) != ""  # --units is a CSV's: G-code has its own
    assert units_hint("G21\n" + metres, "m", why) == ""
    assert units_hint(metres.replace("X1.6", "X5"), "m", why) == ""
    assert units_hint(metres, "m", "the tension margin is -1 N") == ""
    assert units_hint("G0 X1 (open\n", "m", why) == ""  # not read: no hint
    f = tmp_path / "metres.ngc"
    f.write_text(metres)
    assert main(["path", "check", str(f), "--config", str(ROOT / "config" / "rowc.toml")]) == 2
    err = capsys.readouterr().err
    assert "line 2 (the end of segment 1): waypoint [0.0015, 0.0004, 0.0006" in err
    assert "a file in metres?" in err


@pytest.mark.parametrize("name", CAM_FILES)
def test_cam_and_slicer_style_files_pass_the_offline_check(name, capsys):
    cfg = str(ROOT / "config" / "rowc.toml")
    assert main(["path", "check", str(DATA / name), "--config", cfg]) == 0
    out = capsys.readouterr().out
    assert "ok: the path holds" in out


def test_a_cam_style_file_is_played_on_the_simulated_robot(rowc):
    """slicer_style.gcode in lock-step: the path done, the reference on its arcs (within the
    tolerance and the blends' rounding), the simulated platform close to the reference."""
    from test_operating import enabled, events

    text = (DATA / "slicer_style.gcode").read_text()
    with enabled(rowc) as cl:
        c = cl.controller
        cl.command("path", text=text, name="slicer")
        ref = []
        cl.run(40.0, each=lambda cl: ref.append(c.trajectory.position[:3].copy()),
               until=lambda cl: c.data.path_state == "done" and c.data.state.value == "enabled")
        assert c.data.path_state == "done" and c.data.state.value == "enabled", events(cl)[-5:]
        a = cl.arrays()
        moving = np.array([s == "moving" for s in a["state"]])
        err = np.linalg.norm(a["p_true"] - a["p_des"], axis=1)[moving]
        assert err.max() < 0.5e-3, err.max()
    p = np.array(ref)
    # the right half-circle: x beyond 1650 mm, about (1650, 570) in x-z, radius 50 mm
    right = p[p[:, 0] > 1.6505]
    assert len(right) > 50
    r = np.hypot(right[:, 0] - 1.65, right[:, 2] - 0.57)
    assert np.abs(r - 0.05).max() < 2e-3  # chords within 0.1 mm, blended corners rounded
    assert p[:, 0].max() == pytest.approx(1.7, abs=2e-3)
