"""Benchmark: the controller's compute per cycle, by phase (lock-step against the simulated
robot, so the simulator's time is not counted): the window-cleaning robot with the barycenter
and with SOTDA (ν = 0.9), and the Sensors 2019 robot with its two grippers (energy TDA).

Run: ``.venv/bin/python benchmarks/bench_loop.py``.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import machine_line

from cdprctl.control.controller import PHASES
from cdprctl.model import load_robot
from cdprctl.tda import TDAMethod, TDAOptions
from sim_backend.closed_loop import ClosedLoop

CONFIG = Path(__file__).resolve().parents[1] / "config"


def main() -> None:
    logging.getLogger("cdprctl.drivers").setLevel(logging.ERROR)
    print(machine_line())
    rowc = load_robot(CONFIG / "rowc.toml")
    grip = load_robot(CONFIG / "seed000_grippers.toml")
    cases = (
        ("rowc barycenter", rowc, TDAOptions(method=TDAMethod.BARYCENTER), [1.8, 0.35, 0.5]),
        ("rowc sotda nu=0.9", rowc, TDAOptions(method=TDAMethod.SOTDA, nu=0.9), [1.8, 0.35, 0.5]),
        # the Sensors 2019 robot with its two grippers held: energy TDA, J_weight, grasp sensing
        ("seed000_grippers energy", grip, None, [7.05, 4.0, 1.5]),
    )
    for label, model, tda, goal in cases:
        with ClosedLoop(model, tda) as cl:
            cl.startup()
            cl.command("enable")
            cl.run(0.3)
            rpy = np.array(model.home.rpy, dtype=float)  # the move keeps the home orientation
            cl.command("move", pose=np.concatenate([goal, rpy]))
            c = cl.controller
            phases = []
            for _ in range(2500):  # 5 s: the move and the hold after it
                t = cl.net.time
                c.step(t)
                cl.net.advance(cl.period)
                phases.append(c.phase_us.copy())
            ph = np.array(phases)
            total = ph.sum(axis=1)
            print(
                f"\n{label}: state {c.state.value}; compute per cycle median "
                f"{np.median(total):.0f} us, p99 {np.percentile(total, 99):.0f} us"
            )
            print(
                "  "
                + ", ".join(
                    f"{n} {np.median(ph[:, k]):.0f}/{np.percentile(ph[:, k], 99):.0f}"
                    for k, n in enumerate(PHASES)
                )
                + " (median/p99 us)"
            )


if __name__ == "__main__":
    main()
