"""The wrench-feasible workspace (cdprctl.tda.workspace, ``cdprctl workspace``) against an
independent linear programme on every shipped robot, and brute force for r = 1."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from cdprctl.cli import main
from cdprctl.core.rotation import rpy_to_matrix
from cdprctl.geometry.kinematics import wrench_matrix
from cdprctl.robot_file import load_robot
from cdprctl.tda.workspace import Grid, Margins, hold_wrench, wrench_feasible_workspace

ROOT = Path(__file__).resolve().parents[2]
ROBOTS = sorted(p.name for p in (ROOT / "config").glob("*.toml"))


def lp_feasible(W, w, lo, hi) -> bool:
    """Independent verdict: is there t in [lo, hi] with W t = w (HiGHS, no objective)?"""
    res = linprog(np.zeros(W.shape[1]), A_eq=W, b_eq=w, bounds=list(zip(lo, hi, strict=True)),
                  method="highs")  # fmt: skip
    return res.status == 0


@pytest.mark.parametrize("name", ROBOTS)
def test_verdicts_agree_with_an_independent_lp(name):
    model = load_robot(ROOT / "config" / name)
    rng = np.random.default_rng(20)
    grid = Grid.around(model, 12)
    rpy = np.array(model.home.rpy) + rng.uniform(-0.05, 0.05, 3)
    R = rpy_to_matrix(*rpy)
    ext = rng.uniform(-20, 20, 6) * np.array([1, 1, 1, 0.1, 0.1, 0.1])
    res = wrench_feasible_workspace(model, grid, R, ext)
    w = hold_wrench(model, R, ext)
    span = float(np.min(model.tension_max - model.tension_min))
    near, checked, feasible = 0, 0, 0
    for i in rng.choice(len(res.points), 250, replace=False):
        margin = res.margin[i]
        if not np.isfinite(margin):
            continue
        W = wrench_matrix(model, res.points[i], R)
        verdict = lp_feasible(W, w, model.tension_min, model.tension_max)
        if abs(margin) < 1e-6 * span:  # on the boundary: either verdict is right
            near += 1
            continue
        checked += 1
        feasible += verdict
        assert verdict == (margin >= 0.0), (name, res.points[i], margin)
        # the margin itself: shrinking every bound by it is just feasible, by a bit more not
        if margin > 1e-3 and margin < span / 2:
            assert lp_feasible(W, w, model.tension_min + margin - 1e-3,
                               model.tension_max - margin + 1e-3)  # fmt: skip
            assert not lp_feasible(W, w, model.tension_min + margin + 1e-3,
                                   model.tension_max - margin - 1e-3)  # fmt: skip
    print(f"{name}: {checked} verdicts agree ({feasible} feasible), {near} on the boundary")
    assert checked > 150 and near <= 5


def test_redundancy_one_uses_the_lp_and_agrees_with_brute_force():
    """7 cables (CAROCA without its last): t = t0 + n λ, the margin is the best λ of
    min_k(c_k − a_k λ), a 1-D problem solved exactly at every pairwise crossing."""
    base = load_robot(ROOT / "config" / "caroca.toml")
    model = dataclasses.replace(base, cables=base.cables[:7])
    calc = Margins(model)
    assert calc.method == "lp"
    rng = np.random.default_rng(7)
    R = model.home.rotation
    w = hold_wrench(model, R, np.zeros(6))
    lo, hi = model.tension_min, model.tension_max
    for _ in range(30):
        p = model.home.position + rng.uniform(-0.6, 0.6, 3)
        W = wrench_matrix(model, p, R)
        t0 = np.linalg.lstsq(W, w, rcond=None)[0]
        n = np.linalg.svd(W)[2][-1]
        # lines: t_i − lo_i = (t0_i − lo_i) + n_i λ and hi_i − t_i = (hi_i − t0_i) − n_i λ
        c = np.concatenate([t0 - lo, hi - t0])
        a = np.concatenate([n, -n])
        cands = [(c[j] - c[k]) / (a[k] - a[j]) for j, k in itertools.combinations(range(14), 2)
                 if abs(a[k] - a[j]) > 1e-12]  # fmt: skip
        best = max(min(c + a * lam) for lam in cands)
        assert calc.at(p, R, w) == pytest.approx(best, abs=1e-6), p


def test_grid_order_volume_and_degenerate_points():
    model = load_robot(ROOT / "config" / "rowc.toml")
    g = Grid((0.0, 0.3, 0.2), (2.0, 0.4, 0.6), (3, 2, 2))
    pts = g.points()
    assert pts[:3, 0].tolist() == [0.0, 1.0, 2.0] and np.all(pts[:3, 1] == 0.3)  # x fastest
    assert pts[3, 1] == 0.4 and pts[6, 2] == 0.6
    assert g.cell_volume() == pytest.approx(1.0 * 0.1 * 0.4)
    res = wrench_feasible_workspace(model, g, model.home.rotation, np.zeros(6))
    assert res.volume == pytest.approx(res.feasible.sum() * 0.04)
    # an attachment on its anchor: a cable of zero length, no verdict but "not feasible"
    calc = Margins(model)
    R = model.home.rotation
    at = model.anchors[0] - R @ model.attachments[0]
    assert calc.at(at, R, hold_wrench(model, R, np.zeros(6))) == -math.inf


def test_grid_parse_names_the_part():
    assert Grid.parse("0:1:3,0:0:1,1:2:5").n == (3, 1, 5)
    for bad, words in [("0:1:3,0:1", "x0:x1:nx"), ("0:1:3,a:1:2,0:1:2", "--grid y"),
                       ("0:1:3,0:1:2,1:0:2", "start <= stop"), ("0:1:0,0:1:2,0:1:2", "count")]:
        with pytest.raises(ValueError, match=words):
            Grid.parse(bad)


def test_a_value_starting_with_a_minus_is_a_value(capsys):
    """``--grid -1.5:1.5:3,...`` and ``--wrench -30,...`` as typed, without ``=`` (argparse
    took them for options: "expected one argument", a newcomer's trial); the same points
    as with ``=``."""
    cfg = str(ROOT / "config" / "caroca.toml")
    spaced = ["--grid", "-1.5:1.5:3,-2:2:3,0.3:2.5:3", "--wrench", "-30,0,0,0,0,0"]
    joined = ["--grid=-1.5:1.5:3,-2:2:3,0.3:2.5:3", "--wrench=-30,0,0,0,0,0"]
    outs = []
    for args in (spaced, joined):
        assert main(["workspace", "--config", cfg, *args, "--json"]) == 0
        outs.append(json.loads(capsys.readouterr().out))
    for out in outs:  # the timings apart
        out.pop("seconds", None), out.pop("clearance_seconds", None)
    assert outs[0] == outs[1] and outs[0]["points"][0] == [-1.5, -2.0, 0.3]


def test_the_measure_is_in_the_grids_own_unit(capsys):
    """A planar grid's feasible set is an area (m²), a line's a length (m), one point's
    nothing: a newcomer read "0.2 m³ at 0.1 m³ per point" for two points on a line."""
    cfg = str(ROOT / "config" / "rowc.toml")
    for grid, words in (("1.4:1.6:3,0.35:0.35:1,0.5:0.7:3", "(0.09 m² at 0.01 m² per point)"),
                        ("1.4:1.6:3,0.35:0.35:1,0.59:0.59:1", "(0.3 m at 0.1 m per point)"),
                        ("1.5:1.5:1,0.35:0.35:1,0.59:0.59:1", "1 of 1 points wrench-feasible;")):
        assert main(["workspace", "--config", cfg, "--grid", grid]) == 0
        out = capsys.readouterr().out
        assert words in out and "m³" not in out, out


def test_cli_json_and_plot(tmp_path, capsys):
    rc = main(["workspace", "--config", str(ROOT / "config" / "rowc.toml"), "--wrench",
               "0,30,0,0,0,0", "--grid", "0.5:2.5:5,0.35:0.35:1,0.3:0.7:3", "--json",
               "--plot", str(tmp_path)])  # fmt: skip
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    assert len(out["points"]) == len(out["feasible"]) == len(out["margin"]) == 15
    assert out["points"][1] == [1.0, 0.35, 0.3]
    assert out["volume"] == pytest.approx(sum(out["feasible"]) * 0.5 * 0.2)
    assert all(f == (m >= 0) for f, m in zip(out["feasible"], out["margin"], strict=True))
    assert (tmp_path / "slices_xy.png").stat().st_size > 10_000
    rc = main(["workspace", "--config", str(ROOT / "config" / "rowc.toml"), "--wrench", "1,2"])
    assert rc == 2
    assert "--wrench = '1,2' must be 6 finite numbers (N, N·m)" in capsys.readouterr().err


def _homes(fig) -> list[str]:
    """The titles of the slices that draw the home star."""
    return [ax.get_title() for ax in fig.axes
            if any(line.get_marker() == "*" for line in ax.get_lines())]  # fmt: skip


def test_the_home_star_only_on_the_slice_through_home(rowc):
    """A slice 1 m above home draws no home star (it was drawn on every slice, as if home lay
    on each); the slice through home (within half a spacing) draws it; and the slice through
    home is among those drawn even when the spread of picks would step over it."""
    import matplotlib.pyplot as plt

    from cdprctl.tda.plots.workspace_plot import slices_figure

    hx, _, hz = rowc.home.position
    # x slices 0.5 m apart, through home and 1 m either side of it
    grid = Grid((hx - 1.0, 0.3, 0.3), (hx + 1.0, 0.4, 0.7), (5, 3, 3))
    res = wrench_feasible_workspace(rowc, grid, rowc.home.rotation, np.zeros(6))
    fig = slices_figure(rowc, res, res.margin.reshape(3, 3, 5), 0, "t")
    titles = [ax.get_title() for ax in fig.axes if ax.get_title().startswith("x =")]
    assert f"x = {hx - 1.0:.3g} m" in titles and f"x = {hx + 1.0:.3g} m" in titles
    assert _homes(fig) == [f"x = {hx:.3g} m (home)"]  # not on the slices 1 m away
    plt.close(fig)
    # the grid starts 0.3 m past home (spacing 0.5 m): home is on none of its slices
    off = Grid((hx + 0.3, 0.3, 0.3), (hx + 1.3, 0.4, 0.7), (3, 3, 3))
    res = wrench_feasible_workspace(rowc, off, rowc.home.rotation, np.zeros(6))
    fig = slices_figure(rowc, res, res.margin.reshape(3, 3, 3), 0, "t")
    assert [ax for ax in fig.axes if ax.get_title().startswith("x =")]
    assert _homes(fig) == []
    plt.close(fig)
    # 40 z slices of which 9 are drawn: the one through home is one of them
    fine = Grid((1.0, 0.3, 0.0), (2.0, 0.4, 1.4), (3, 3, 40))
    res = wrench_feasible_workspace(rowc, fine, rowc.home.rotation, np.zeros(6))
    fig = slices_figure(rowc, res, res.margin.reshape(40, 3, 3), 2, "t")
    step = 1.4 / 39
    near = fine.axes()[2][round(hz / step)]
    assert _homes(fig) == [f"z = {near:.3g} m (home)"]
    plt.close(fig)



@pytest.mark.parametrize("robot, rpy", [("rowc", "0,0,0.3"), ("rowc", "0.2,0.2,0"),
                                        ("seed000", "-0.1,0,0")])  # fmt: skip
def test_an_orientation_beyond_max_angle_is_refused_in_one_line(robot, rpy, capsys):
    """The angle from the robot's home orientation (scipy's rotations, apart from the
    project's), not a coordinate's size: seed000's home is rolled 30°, so its roll −0.1 rad
    is 0.62 rad from it. Refused beyond ``max_angle`` in one line, exit 2; at it (rowc turned
    0.2 rad about z), taken."""
    from scipy.spatial.transform import Rotation

    model = load_robot(ROOT / "config" / f"{robot}.toml")
    cfg = str(ROOT / "config" / f"{robot}.toml")
    given = Rotation.from_euler("xyz", [float(v) for v in rpy.split(",")])
    angle = (given * Rotation.from_euler("xyz", model.home.rpy).inv()).magnitude()
    assert angle > model.workspace.max_angle
    assert main(["workspace", "--config", cfg, "--rpy", rpy, "--grid", "1:1:1,1:1:1,1:1:1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    limit = model.workspace.max_angle
    assert err.startswith(f"cdprctl workspace: error: --rpy = '{rpy}': {angle:.4f} rad "
                          f"({np.degrees(angle):.2f}°) from the home orientation, beyond "
                          f"[workspace] max_angle = {limit:g} rad ({np.degrees(limit):.2f}°) "
                          f"of {robot}")  # fmt: skip
    if robot == "rowc":
        assert main(["workspace", "--config", cfg, "--rpy", "0,0,0.2", "--grid",
                     "1.5:1.5:1,0.35:0.35:1,0.59:0.59:1"]) == 0  # fmt: skip


@pytest.mark.parametrize("rpy, words", [
    ("0,0,30", "yaw = 30 is taken in radians and is beyond pi; did you mean degrees? 30° = "
               "0.5236 rad: write it 30deg or 0.5236"),
    ("-90,0,0", "roll = -90 is taken in radians and is beyond pi; did you mean degrees? -90° = "
                "-1.5708 rad"),
    ("0,0,x", "must be 3 finite numbers (rad, or each ending in deg)"),
    ("0,0", "must be 3 finite numbers (rad, or each ending in deg)"),
])  # fmt: skip
def test_rpy_is_radians_and_degrees_meant_as_radians_are_refused(rpy, words, capsys):
    """``--rpy 0,0,30`` once turned rowc by 30 rad (1.4159 rad once wrapped) and said so only
    through max_angle: a bare angle beyond pi is refused in one line with its value in
    radians, exit 2, before any point is computed."""
    cfg = str(ROOT / "config" / "rowc.toml")
    assert main(["workspace", "--config", cfg, "--rpy", rpy, "--grid", "1:1:1,1:1:1,1:1:1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"cdprctl workspace: error: --rpy = '{rpy}': {words}"), err


def test_rpy_in_degrees_with_the_deg_suffix(capsys):
    """``0,0,10deg`` is rowc turned 10° about z: the orientation the JSON reports (rad) is
    scipy's rotation of 10° about z, and the verdict the one of the same angle in radians;
    "°" stands for "deg"."""
    from scipy.spatial.transform import Rotation

    cfg = str(ROOT / "config" / "rowc.toml")
    grid = "1.2:1.8:3,0.35:0.35:1,0.5:0.7:3"
    out = {}
    for rpy in ("0,0,10deg", "0deg, 0, 10°", "0,0,0.17453292519943295"):
        assert main(["workspace", "--config", cfg, "--rpy", rpy, "--grid", grid, "--json"]) == 0
        out[rpy] = json.loads(capsys.readouterr().out)
    said = Rotation.from_euler("xyz", out["0,0,10deg"]["rpy"])
    assert (said * Rotation.from_euler("z", 10, degrees=True).inv()).magnitude() < 1e-12
    for rpy in ("0deg, 0, 10°", "0,0,0.17453292519943295"):
        assert out[rpy]["rpy"] == pytest.approx(out["0,0,10deg"]["rpy"], abs=1e-15)
        assert out[rpy]["margin"] == out["0,0,10deg"]["margin"]
