"""``cdprctl demo``: the main job of ``make run`` — the offline tools on the bundled robots."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cdprctl.commands.check_config import summary
from cdprctl.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model import load_robot
from cdprctl.stiffness import stiffness_matrix

CONFIG_DIR = Path(__file__).resolve().parents[2] / "config"


def run(config_dir: Path = CONFIG_DIR) -> int:
    seed = load_robot(config_dir / "seed000.toml")
    print(summary(seed))
    print()
    rowc = load_robot(config_dir / "rowc.toml")
    data = KinematicsData(rowc)
    inverse_kinematics(rowc, data, rowc.home.position, rowc.home.rotation)
    K = stiffness_matrix(rowc, data, np.full(rowc.n_cables, 80.0))
    dX = np.linalg.solve(K, np.array([0.0, 50.0, 0.0, 0.0, 0.0, 0.0]))
    print(
        f"{rowc.name}: at home, all cables at 80 N, a 50 N force along y moves the platform by "
        f"δp = {np.round(dX[:3] * 1000, 3).tolist()} mm (K = Kp + Ka, Picard et al. 2020 eq. 3-4)"
    )
    return 0
