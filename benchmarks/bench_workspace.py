"""Benchmark: the wrench-feasible workspace of a 40×40×40 grid (``cdprctl workspace``), the
compiled polygon LP (r = 2) against ``scipy.optimize.linprog`` (HiGHS) on the same points; and
the interference check of the same grid (issue 67) the command adds, as a fraction of it.

Run: ``.venv/bin/python benchmarks/bench_workspace.py [--all]``. linprog runs on a seeded
sample of 2000 of the grid's points (``--all``: every point, minutes) and its grid time is
that per-point median × 64000; the verdicts of both on the sample are compared.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import machine_line

from cdprctl.geometry.kinematics import KinematicsData, ik_kernel
from cdprctl.robot_file import load_robot
from cdprctl.tda.workspace import Grid, hold_wrench, margin_lp, wrench_feasible_workspace

CONFIG = Path(__file__).resolve().parents[1] / "config"


def main() -> None:
    everything = "--all" in sys.argv
    print(machine_line())
    for name, n in (("rowc", 40), ("seed000", 40), ("caroca", 40)):
        model = load_robot(CONFIG / f"{name}.toml")
        grid = Grid.around(model, n)
        R = model.home.rotation
        wrench_feasible_workspace(model, Grid.around(model, 2), R, np.zeros(6))  # load kernels
        runs = [wrench_feasible_workspace(model, grid, R, np.zeros(6)) for _ in range(3)]
        res = runs[0]
        poly_s = float(np.median([r.seconds for r in runs]))
        clear_s = float(np.median([r.clearance_seconds for r in runs]))
        rng = np.random.default_rng(0)
        idx = np.arange(len(res.points)) if everything else rng.choice(len(res.points), 2000,
                                                                        replace=False)  # fmt: skip
        kin = KinematicsData(model)
        w = hold_wrench(model, R, np.zeros(6))
        per, agree, finite = [], 0, 0
        for i in idx:
            t0 = time.perf_counter()
            ik_kernel(kin.arrays, res.points[i], R)
            m = margin_lp(kin.W, w, model.tension_min, model.tension_max)
            per.append(time.perf_counter() - t0)
            if np.isfinite(res.margin[i]):
                finite += 1
                agree += (m >= 0.0) == (res.margin[i] >= 0.0)
        lp_point = float(np.median(per))
        lp_grid = float(np.sum(per)) if everything else lp_point * len(res.points)
        print(
            f"{name:8s} {len(res.points)} points: polygon {poly_s:.2f} s "
            f"({poly_s / len(res.points) * 1e6:.1f} µs/point, median of 3); linprog "
            f"{lp_point * 1e6:.0f} µs/point median → {lp_grid:.0f} s "
            f"{'measured' if everything else 'for the grid (from 2000 points)'}; "
            f"ratio {lp_grid / poly_s:.0f}x; verdicts agree on {agree}/{finite}; "
            f"{int(res.feasible.sum())} feasible, {res.volume:.3g} m³; interference "
            f"{clear_s:.2f} s ({clear_s / len(res.points) * 1e6:.1f} µs/point, "
            f"{(poly_s + clear_s) / poly_s:.2f}x the wrench-feasible alone), "
            f"{int(res.usable.sum())} both"
        )


if __name__ == "__main__":
    main()
