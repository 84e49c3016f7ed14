"""rowc's crossed pairs pass each other (issue 67): the cables at least the file's clearance
(5 mm) apart, and from the platform's body, over the documented workspace and orientations,
by the brute force of ``tools/clearance_check.py`` (numpy only, each cable sampled every
0.1 mm, apart from ``cdprctl/geometry/interference.py``). The grid here: the ``[workspace]`` box's
corners and the paper's X0, at the home orientation and turned ``max_angle`` about the 26 axes
of a cube (the full grid, every 0.1 m x 10 mm x 0.1 m and 83 orientations: docs/clearance.md).
The same poses against the kernel (the two agree within the sampling's 0.05 mm), and the
geometry before the offsets, which the brute force finds crossing (the check can fail)."""

from __future__ import annotations

import copy
import itertools
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from cdprctl.geometry.interference import BODY, CABLE, Interference
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.robot_file import load_robot, parse_robot
from cdprctl.robot_file.loader import read_merged

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import clearance_check as brute  # noqa: E402

PAIRS = ((0, 1), (2, 3), (4, 5), (6, 7))


@pytest.fixture(scope="module")
def rowc():
    return load_robot(ROOT / "config" / "rowc.toml")


def grid(model):
    """The box's 8 corners and X0, each at the home orientation and at ``max_angle`` about
    the 26 axes: 243 poses."""
    lo, hi = model.workspace.position_min, model.workspace.position_max
    points = [np.array(c) for c in itertools.product(*zip(lo, hi, strict=True))]
    points.append(model.home.position)
    turns = brute.turns(model.workspace.max_angle, [1.0], 0)
    return [(p, dR @ model.home.rotation) for _, _, dR in turns for p in points]


def test_every_variant_of_rowc_has_its_geometry():
    """rowc_1khz and rowc_odrive take rowc's cables and body (``base``): what is checked here
    holds for them."""
    base = load_robot(ROOT / "config" / "rowc.toml")
    for name in ("rowc_1khz", "rowc_odrive"):
        model = load_robot(ROOT / "config" / f"{name}.toml")
        assert np.array_equal(model.anchors, base.anchors)
        assert np.array_equal(model.attachments, base.attachments)
        assert model.interference.clearance == base.interference.clearance
        assert [b.name for b in model.interference.body] == [b.name for b in base.interference.body]
        for mine, theirs in zip(model.interference.body, base.interference.body, strict=True):
            assert np.array_equal(mine.half_extents, theirs.half_extents)
            assert np.array_equal(mine.centre, theirs.centre)


def test_rowc_clears_over_its_workspace_by_brute_force(rowc):
    check = brute.Clearance(rowc)
    kernel, kin = Interference(rowc), KinematicsData(rowc)
    cable = kernel.checks[:, 0] == CABLE
    body = kernel.checks[:, 0] == BODY
    clearance = rowc.interference.clearance
    assert clearance == pytest.approx(0.005)
    worst = {"cables": np.inf, "body": np.inf}
    for p, R in grid(rowc):
        d = check.at(p, R)
        inverse_kinematics(rowc, kin, p, R)
        kernel.update(kin)
        for key, rows in (("cables", cable), ("body", body)):
            exact = kernel.distance[rows].min()
            # sampling never finds less than the exact least, and at most half a step more
            assert exact - 1e-9 <= d[key][0] <= exact + brute.STEP / 2 + 1e-9
            worst[key] = min(worst[key], d[key][0])
    assert check.least["cables"].below == check.least["body"].below == 0
    assert worst["cables"] >= clearance and worst["body"] >= clearance
    # the grid reaches the full grid's least (docs/interference.md): cables 7-8 turned about -z
    assert worst["cables"] == pytest.approx(0.0129, abs=1e-4)


def test_the_shipped_geometry_before_the_offsets_crosses(rowc):
    """Each pair's anchors and attachments sharing x and z again (the file before issue 67):
    its two cables in one plane, through each other at the home pose."""
    data = copy.deepcopy(read_merged(ROOT / "config" / "rowc.toml"))
    for i, j in PAIRS:
        a, b = data["cables"][i], data["cables"][j]
        for key in ("anchor", "attachment"):
            b[key] = [a[key][0], b[key][1], a[key][2]]
    old = parse_robot(data, "rowc before the offsets")
    d = brute.Clearance(old).at(old.home.position, old.home.rotation)
    assert d["cables"][0] < 1e-4


def test_rowc_holds_the_lateral_force_at_x0(rowc):
    """ARK 2020's 50 N along y plus the weight at X0 with every tension in [10, 200] N: a
    tension vector exists (scipy's linprog, maximising the least margin to the limits)."""
    kin = KinematicsData(rowc)
    inverse_kinematics(rowc, kin, rowc.home.position, rowc.home.rotation)
    w = -(np.array([0.0, 50.0, 0.0, 0.0, 0.0, 0.0]) + rowc.gravity_wrench(rowc.home.rotation))
    lo, hi = rowc.tension_min, rowc.tension_max
    m = rowc.n_cables
    # variables: t (m), s; maximise s with lo + s <= t <= hi - s, W t = w
    c = np.zeros(m + 1)
    c[-1] = -1.0
    A_ub = np.block([[-np.eye(m), np.ones((m, 1))], [np.eye(m), np.ones((m, 1))]])
    b_ub = np.concatenate([-lo, hi])
    A_eq = np.hstack([kin.W, np.zeros((6, 1))])
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=w, bounds=[(None, None)] * (m + 1))
    assert res.status == 0
    assert res.x[-1] == pytest.approx(26.0, abs=0.05)  # N: rowc.toml's header
