"""What ``cdprctl check-config`` and ``cdprctl path check`` say of the cables' clearance (issue
67): the least distance with its pair and the limit, measured by brute force apart from the
project's kernel (``tools/clearance_check.py``: numpy, each cable sampled every 0.1 mm); and a
path that comes closer than the limit refused, naming the file's line and the pair. The cell
here: rowc with a lamp (a 10 mm cube) beside cable 1's sweep between x = 1.5 and 2.1 m."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

from cdprctl.cli import main
from cdprctl.core.rotation import exp_so3
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import clearance_check as brute  # noqa: E402

LAMP = """
[[cell.obstacles]]
name = "the lamp"
kind = "box"
centre = [1.04, 0.34, {z}]  # m
half_extents = [0.005, 0.005, 0.005]  # m
"""


def _pair(check, p, R, words: str) -> float:
    """m: the brute force's distance between the two cables ``words`` names ("cables 5 and
    6", or "cable 7 and cable 8" where the names say "cable") at the pose ``p``, ``R`` (a
    symmetric robot ties pairs: the one printed must be one)."""
    names = [c.name for c in check.model.cables]
    i, j = (names.index(n) for n in words.removeprefix("cables ").split(" and "))
    from cdprctl.geometry.kinematics import inverse_kinematics

    inverse_kinematics(check.model, check.kin, p, R)
    B = p + np.asarray(check.model.attachments) @ R.T
    E = np.array(check.kin.exit_points, dtype=float)
    return brute.sampled(B[i], E[i], brute.to_segment(B[j], E[j]), brute.STEP)


def _mm(text: str, after: str) -> float:
    return float(re.search(re.escape(after) + r" ([0-9.]+) mm", text).group(1)) / 1e3


@pytest.mark.parametrize("name", ["rowc", "caroca", "cogiro"])
def test_check_config_prints_the_clearance_at_home_and_over_the_box(name, capsys):
    """The home pose's least distance and the box's least at the home orientation, each as
    the brute force finds it at the pose printed, with its pair; the box's least no larger
    than the brute force at the box's corners. CAROCA's low corner is under the limit and
    says so."""
    path = ROOT / "config" / f"{name}.toml"
    model = load_robot(path)
    assert main(["check-config", str(path)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("clearance"))
    check = brute.Clearance(model)
    R = model.home.rotation
    home = check.at(model.home.position, R)
    least = min(home.values())
    assert _mm(line, "at home") == pytest.approx(least[0], abs=6e-5)
    said = re.search(r"at home [0-9.]+ mm \((.+?)\)", line).group(1)
    assert _pair(check, model.home.position, R, said) == pytest.approx(least[0], abs=6e-5)
    box = re.search(r"orientation ([0-9.]+) mm \((.+?) at \[(.+?)\] m\)", line)
    at = np.array([float(v) for v in box.group(3).split(",")])
    there = min(check.at(at, R).values())
    assert float(box.group(1)) / 1e3 == pytest.approx(there[0], abs=6e-5)
    assert _pair(check, at, R, box.group(2)) == pytest.approx(there[0], abs=6e-5)
    ws = model.workspace
    for corner in np.array(np.meshgrid(*zip(ws.position_min, ws.position_max, strict=True)
                                       )).reshape(3, -1).T:  # fmt: skip
        assert min(check.at(corner, R).values())[0] >= float(box.group(1)) / 1e3 - 6e-5
    level, tilted = line.split("; over the workspace box turned")
    assert ("UNDER the limit" in level.split("home orientation")[1]) == (
        float(box.group(1)) / 1e3 < model.interference.clearance)  # fmt: skip
    assert "limit 5.00 mm ([interference] clearance)" in line
    # turned max_angle: the least printed is the brute force's at the pose printed
    turned = re.search(r"turned ([0-9.]+) rad ([0-9.]+) mm \((.+?) at \[(.+?)\] m turned about "
                       r"([+-])([xyz])\)", line)  # fmt: skip
    assert turned and float(turned.group(1)) == model.workspace.max_angle, line
    at = np.array([float(v) for v in turned.group(4).split(",")])
    axis = np.eye(3)["xyz".index(turned.group(6))] * (1.0 if turned.group(5) == "+" else -1.0)
    R = exp_so3(axis * model.workspace.max_angle) @ model.home.rotation
    there = min(check.at(at, R).values())
    assert float(turned.group(2)) / 1e3 == pytest.approx(there[0], abs=6e-5)
    assert ("UNDER the limit" in tilted) == (there[0] < model.interference.clearance)


def _lamp_robot(tmp_path, z: float) -> str:
    f = tmp_path / "rowc_lamp.toml"
    f.write_text(f'base = "{ROOT / "config" / "rowc.toml"}"\n' + LAMP.format(z=z))
    return str(f)


def test_path_check_refuses_a_path_into_the_lamp_naming_the_line_and_pair(tmp_path, capsys):
    cfg = _lamp_robot(tmp_path, 0.294)
    path = tmp_path / "into.csv"
    path.write_text("x, y, z\n1.5, 0.35, 0.65\n1.5, 0.35, 0.59\n2.1, 0.35, 0.59\n")
    assert main(["path", "check", str(path), "--config", cfg]) == 2
    err = capsys.readouterr().err
    assert f"{path} rejected: line 4 (segment 3): at t = " in err
    assert "cable 1 and the lamp: " in err and "under the clearance 5.00 mm" in err


def test_path_check_prints_the_least_clearance_the_brute_force_finds(tmp_path, capsys):
    """The lamp 44 mm lower: cable 1 passes it clear; the least printed is the brute force's
    least along the straight line (every 1 mm, each cable every 0.1 mm), within 0.1 mm."""
    cfg = _lamp_robot(tmp_path, 0.25)
    path = tmp_path / "past.csv"
    path.write_text("x, y, z\n2.1, 0.35, 0.59\n")
    assert main(["path", "check", str(path), "--config", cfg]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if "least clearance" in x)
    printed = _mm(line, "least clearance")
    assert "cable 1 and the lamp (line 2, t = " in line
    assert "limit 5.00 mm ([interference] clearance)" in line
    model = load_robot(cfg)
    check = brute.Clearance(model)
    xs = np.arange(1.5, 2.1 + 1e-9, 0.001)
    least = min(check.at(np.array([x, 0.35, 0.59]), model.home.rotation)["cell"][0] for x in xs)
    assert 5e-3 < least < 20e-3  # the lamp is what comes closest, clear of the limit
    assert printed == pytest.approx(least, abs=1e-4)


def test_check_config_warns_when_the_home_pose_is_under_the_clearance(tmp_path, capsys):
    """seed000's home pose: cable 2 3.61 mm from the platform's cube (the brute force), under
    the 5 mm limit. check-config does not say OK: the first line counts the warnings, each
    follows it naming the pair, the distance and the limit; exit 0 (``cdprctl run`` accepts
    the file: docs/clearance.md), 1 under ``--strict``. rowc, clear everywhere, says OK and
    passes ``--strict``; rowc asked for 40 mm (more than its 33.4 mm at home) warns too."""
    path = ROOT / "config" / "seed000.toml"
    model = load_robot(path)
    check = brute.Clearance(model)
    d, what = min(check.at(model.home.position, model.home.rotation).values())
    assert 3e-3 < d < model.interference.clearance  # the case of the issue, as measured apart
    assert main(["check-config", str(path)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"{path}: valid, with 3 warnings"
    home = re.fullmatch(r"  warning: at the home pose (.+?) are ([0-9.]+) mm apart, under the "
                        r"\[interference\] clearance 5\.00 mm: .*", out[1])  # fmt: skip
    assert home, out[1]
    assert home.group(1) == what == "cable 2 and the platform's cube"
    assert float(home.group(2)) / 1e3 == pytest.approx(d, abs=6e-5)
    box = re.fullmatch(r"  warning: (\d+) of 1331 poses of the \[workspace\] box at the home "
                       r"orientation are under .*", out[2])  # fmt: skip
    assert box and 0 < int(box.group(1)) <= 1331, out[2]
    turned = re.fullmatch(r"  warning: (\d+) of 7986 poses of the \[workspace\] box turned "
                          r"0\.6 rad are under .*", out[3])  # fmt: skip
    assert turned and 0 < int(turned.group(1)) <= 7986, out[3]
    assert not any(line.endswith(": OK") for line in out)
    assert main(["check-config", "--strict", str(path)]) == 1
    assert "3 warnings (above) and --strict: exit 1" in capsys.readouterr().err

    rowc = ROOT / "config" / "rowc.toml"
    assert main(["check-config", "--strict", str(rowc)]) == 0
    assert capsys.readouterr().out.splitlines()[0] == f"{rowc}: OK"
    tight = tmp_path / "rowc_40mm.toml"
    tight.write_text(f'base = "{rowc}"\n[interference]\nclearance = 0.040\n')
    assert main(["check-config", str(tight)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].endswith(": valid, with 3 warnings")
    assert "under the [interference] clearance 40.00 mm" in out[1]


def test_check_config_lists_the_body_and_the_cell_by_name_and_table(tmp_path, capsys):
    """Which obstacles the file gave, each by the name messages use and by the table a file
    error names (counted from 0): an unnamed obstacle is "obstacle N", N from 1 (a newcomer
    could not tell which number an unnamed box had without a message naming it)."""
    robot = tmp_path / "cell.toml"
    robot.write_text(f'base = "{ROOT / "config" / "rowc.toml"}"\n\n'
                     '[[cell.obstacles]]\nname = "crate"\nkind = "box"\n'
                     "centre = [1.95, 0.35, 0.59]\nhalf_extents = [0.05, 0.05, 0.05]\n\n"
                     '[[cell.obstacles]]\nkind = "plane"\npoint = [0.0, 0.0, -0.2]\n'
                     "normal = [0.0, 0.0, 2.0]\n")  # fmt: skip
    assert main(["check-config", str(robot)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert ("body        platform.body.boxes[0] 'body': centre [0.0, 0.0, 0.0] m, half extents "
            "[0.1, 0.05, 0.1] m") in out  # fmt: skip
    assert ("cell        cell.obstacles[0] 'crate': box, centre [1.95, 0.35, 0.59] m, half "
            "extents [0.05, 0.05, 0.05] m; cell.obstacles[1] 'obstacle 2': plane through "
            "[0.0, 0.0, -0.2] m, normal [0.0, 0.0, 1.0]") in out  # fmt: skip
    assert main(["check-config", str(ROOT / "config" / "cogiro.toml")]) == 0
    out = capsys.readouterr().out.splitlines()
    assert "body        none given ([[platform.body.boxes]])" in out
    assert "cell        no obstacle given ([[cell.obstacles]])" in out
