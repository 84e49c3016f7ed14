"""Benchmark: inverse kinematics + wrench matrix, and warm-started forward kinematics.

Run: ``.venv/bin/python benchmarks/bench_kinematics.py`` (8-cable robots; median and p99 µs).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import machine_line, row, time_calls

from cdprctl.core.rotation import exp_so3
from cdprctl.geometry.forward_kinematics import ForwardKinematics
from cdprctl.geometry.kinematics import KinematicsData, cable_lengths, inverse_kinematics
from cdprctl.robot_file import load_robot

CONFIG = Path(__file__).resolve().parents[1] / "config"


def main() -> None:
    print(machine_line())
    for name in ("rowc", "seed000", "caroca_pulleys"):
        model = load_robot(CONFIG / f"{name}.toml")
        data = KinematicsData(model)
        p, R = model.home.position.copy(), model.home.rotation.copy()
        us = time_calls(lambda: inverse_kinematics(model, data, p, R))  # noqa: B023
        print(row(f"{name}: IK + W (8 cables)", us, 20.0))
        # FK warm-started from the pose one 2 ms control period earlier (0.5 m/s, 0.5 rad/s)
        fk = ForwardKinematics(model)
        p1 = p + np.array([0.001, 0.0, 0.0])
        R1 = exp_so3(np.array([0.0, 0.0, 0.001])) @ R
        lengths = cable_lengths(model, p1, R1)
        us = time_calls(lambda: fk.solve(lengths, p, R), n=5000)  # noqa: B023
        res = fk.solve(lengths, p, R)
        print(row(f"{name}: FK warm start ({res.iterations} it.)", us, 100.0))


if __name__ == "__main__":
    main()
