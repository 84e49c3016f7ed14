"""The shipped robots other than rowc against their clearance (issue 67, docs/clearance.md):
their geometry is the papers' and stays; where a pose of the stated workspace (the
``[workspace]`` box and ``max_angle``) brings two cables, or a cable and the body, under
``[interference] clearance``, the doc says so and the soft limits refuse it. Checked on the
box's corners and the home position, at the home orientation and turned half and all of
``max_angle`` about ±x, ±y, ±z: the brute force of ``tools/clearance_check.py`` (numpy, each
cable sampled every 0.1 mm, apart from the project's kernel) against ``SoftLimits.check``,
the rule every target, move, path and jog keeps."""

from __future__ import annotations

import itertools
import sys
from pathlib import Path

import numpy as np
import pytest

from cdprctl.core.rotation import exp_so3
from cdprctl.motion.limits import SoftLimits
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import clearance_check as brute  # noqa: E402

BAND = 6e-5  # m: the brute force's sampling (≤ 0.05 mm above the exact least) and rounding


def poses(model):
    """(p, rotation vector from home) of the box's corners and the home position, at the home
    orientation and half and all of ``max_angle`` about ±x, ±y, ±z: 117 poses."""
    ws = model.workspace
    points = [np.array(c) for c in itertools.product(*zip(ws.position_min, ws.position_max,
                                                          strict=True))]  # fmt: skip
    points.append(np.asarray(model.home.position, dtype=float))
    turns = [np.zeros(3)] + [f * s * ws.max_angle * np.eye(3)[k] for f in (0.5, 1.0)
                             for k in range(3) for s in (1, -1)]  # fmt: skip
    return [(p, a) for p in points for a in turns]


# robot: (the least at the home pose (m) and what; poses under the clearance on this grid)
EXPECTED = {
    "caroca": ((0.11196, "cables 4 and 5"), 12),
    "caroca_pulleys": ((0.10893, "cables"), 10),
    "cogiro": ((0.39788, "cable"), 3),
    "seed000": ((0.00361, "cable 2 and the platform's cube"), 99),
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_the_soft_limits_refuse_exactly_the_poses_brute_force_finds_under_the_clearance(name):
    model = load_robot(ROOT / "config" / f"{name}.toml")
    limit = model.interference.clearance
    assert limit == pytest.approx(0.005)
    check, lim = brute.Clearance(model), SoftLimits(model)
    grid = poses(model)
    coords = np.array([np.r_[p, a] for p, a in grid])
    _, ok = lim.check(coords)
    nearest = lim.nearest.copy()
    under = 0
    for k, (p, a) in enumerate(grid):
        d, what = min(check.at(p, exp_so3(a) @ model.home.rotation).values())
        assert d - BAND <= nearest[k] <= d + 1e-9, (p, a, d, nearest[k], what)
        if d < limit - BAND:
            under += 1
            assert not ok[k], (p, a, d, what)  # refused, whatever else holds there
        elif d >= limit + BAND:
            assert nearest[k] >= limit
    (home, what), n_under = EXPECTED[name]
    d_home, what_home = min(check.at(model.home.position, model.home.rotation).values())
    assert d_home == pytest.approx(home, abs=BAND) and what_home.startswith(what)
    assert under == n_under  # docs/clearance.md: which poses it cannot reach
