"""``cdprctl workspace`` with the interference-free workspace (issue 67): the compiled pass
over the grid against each point measured on its own (``check_pose``, itself checked against
scipy and dense sampling in tests/geometry/test_interference.py), why each point fails, the
command's summary and JSON, and the plots. CAROCA with a planted box in its cell, so that the
clearance, not the tension, bounds part of the grid."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from cdprctl.cli import main
from cdprctl.geometry.interference import check_pose
from cdprctl.model.interference import Box, InterferenceConfig
from cdprctl.robot_file import load_robot
from cdprctl.tda.workspace import Grid, wrench_feasible_workspace

ROOT = Path(__file__).resolve().parents[2]
PILLAR = """
[[cell.obstacles]]
name = "a pillar"
kind = "box"
centre = [1.0, 0.0, 1.5]
half_extents = [0.1, 0.1, 1.5]
"""


@pytest.fixture(scope="module")
def caroca_pillar():
    model = load_robot(ROOT / "config" / "caroca.toml")
    pillar = Box("a pillar", np.array([1.0, 0.0, 1.5]), np.array([0.1, 0.1, 1.5]), np.eye(3))
    cfg = model.interference
    return dataclasses.replace(
        model, interference=InterferenceConfig(cfg.clearance, cfg.attachment_exclusion, (),
                                               (pillar,)))  # fmt: skip


def test_every_point_is_measured_as_on_its_own(caroca_pillar):
    model = caroca_pillar
    R = model.home.rotation
    res = wrench_feasible_workspace(model, Grid.parse("-2:2:9,-1.5:1.5:7,0.5:2.5:5"), R,
                                    np.zeros(6))  # fmt: skip
    assert 0 < res.clear.sum() < len(res.points)  # the pillar takes a part, not all
    assert np.any(res.feasible & ~res.clear)  # the clearance alone bounds some points
    for i, p in enumerate(res.points):
        g = check_pose(model, p, R)
        assert res.clearance[i] == pytest.approx(g.minimum, abs=1e-12)
        assert res.pairs[res.pair[i]] == g.name(int(g.best[0]))
    assert np.array_equal(res.usable, res.feasible & (res.clearance >= 0.005))
    assert res.usable_volume == pytest.approx(res.usable.sum() * res.grid.cell_volume())


def test_the_command_says_both_workspaces_and_why_points_fail(tmp_path, capsys):
    robot = tmp_path / "caroca_pillar.toml"
    robot.write_text((ROOT / "config" / "caroca.toml").read_text() + PILLAR)
    grid = "-2:2:9,-1.5:1.5:7,0.5:2.5:5"
    assert main(["workspace", "--config", str(robot), f"--grid={grid}", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    feasible, clear = np.array(out["feasible"]), np.array(out["clear"])
    assert out["usable"] == (feasible & clear).tolist() and out["clearance_limit"] == 0.005
    words = {(True, True): "", (False, True): "tension", (True, False): "clearance",
             (False, False): "tension, clearance"}  # fmt: skip
    assert out["why"] == [words[(f, c)] for f, c in zip(feasible, clear, strict=True)]
    blocked = [out["pairs"][k] for k, c in zip(out["pair"], clear, strict=True) if not c]
    assert any(name.endswith("and a pillar") for name in blocked)  # and crossing cables
    assert main(["workspace", "--config", str(robot), f"--grid={grid}", "--plot",
                 str(tmp_path / "plots")]) == 0  # fmt: skip
    said = capsys.readouterr().out
    n_clear, n_both = int(clear.sum()), int((feasible & clear).sum())
    assert f"interference-free (cables, body, cell ≥ 5.00 mm apart): {n_clear} of 315" in said
    assert f"both: {n_both} (" in said and "closest under the clearance: cable " in said
    assert sorted(p.name for p in (tmp_path / "plots").iterdir()) == [
        "feasible_3d.png", "slices_xy.png", "slices_xz.png"]  # fmt: skip
