"""Benchmark: the interference check of one pose (``cdprctl/geometry/interference.py``), after the
inverse kinematics that it reads: µs per pose, median and p99, for rowc (its body), CAROCA and
CoGiRo (their cables only: their files give no body), and each with a cell of three obstacles
(a floor, a tilted wall, a box) to show what obstacles cost.

Run: ``.venv/bin/python benchmarks/bench_interference.py`` (the issue's goal: a few µs a pose).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import machine_line, row, time_calls

from cdprctl.core.rotation import exp_so3, rpy_to_matrix
from cdprctl.geometry.interference import Interference
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model import RobotModel
from cdprctl.model.interference import Box, InterferenceConfig, Plane
from cdprctl.robot_file import load_robot

CONFIG = Path(__file__).resolve().parents[1] / "config"


def cell(model: RobotModel) -> InterferenceConfig:
    lo = model.workspace.position_min
    cfg = model.interference
    return InterferenceConfig(cfg.clearance, cfg.attachment_exclusion, cfg.body, (
        Plane("floor", np.array([0.0, 0.0, lo[2] - 0.3]), np.array([0.0, 0.0, 1.0])),
        Plane("wall", np.array([lo[0] - 0.5, 0.0, 0.0]), np.array([0.9, 0.1, 0.1]) / 0.911),
        Box("box", lo + 0.1, np.array([0.1, 0.2, 0.3]), rpy_to_matrix(0.1, 0.2, 0.3)),
    ))  # fmt: skip


def main() -> None:
    print(machine_line())
    rng = np.random.default_rng(0)
    for name in ("rowc", "caroca", "cogiro"):
        model = load_robot(CONFIG / f"{name}.toml")
        kin = KinematicsData(model)
        # a pose off home (tilted): no shortcut of a symmetric pose
        ws = model.workspace
        p = rng.uniform(ws.position_min, ws.position_max)
        R = exp_so3(np.array([0.05, -0.08, 0.1])) @ model.home.rotation
        inverse_kinematics(model, kin, p, R)
        for label, cfg in (("", model.interference), (" + 3 obstacles", cell(model))):
            check = Interference(model, cfg)
            n = len(check.checks)
            us = time_calls(lambda: check.update(kin))  # noqa: B023
            print(row(f"{name}{label}: {n} checks", us, 5.0))
        us = time_calls(lambda: inverse_kinematics(model, kin, p, R))  # noqa: B023
        print(row(f"{name}: the IK it reads (for scale)", us))


if __name__ == "__main__":
    main()
