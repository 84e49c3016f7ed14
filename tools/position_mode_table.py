"""Prints robots in position mode side by side as a markdown table (lock-step): the demo's four
moves (to one side, home, the other side, home), the simulated platform's tracking error
against the reference, then a lateral force ramped in over 1 s along y: its transient and
what is left after 5 s. ``config/rowc.toml`` (CiA 402 drives) beside
``config/rowc_odrive.toml`` (ODrive axes) by default, at each rate.

    .venv/bin/python tools/position_mode_table.py [--configs A.toml,B.toml] [--rates 250,500]
        [--force 30]
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cdprctl.daemon.scripts import demo_targets  # noqa: E402
from cdprctl.experiments.closed_loop import ClosedLoop, ramped_force  # noqa: E402
from cdprctl.model.robot import RobotModel  # noqa: E402
from cdprctl.robot_file import load_robot  # noqa: E402


def measure(model: RobotModel, force: float) -> dict[str, object]:
    """The demo's moves, then the force: errors in mm, the final state and why."""
    a, b = demo_targets(model)
    with ClosedLoop(model) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(0.5)
        data = cl.controller.data
        for p in (a, model.home.position, b, model.home.position):
            cl.command("move", pose=np.concatenate([p, model.home.rpy]))
            cl.run(3.0)
        arr = cl.arrays()
        err = np.linalg.norm(arr["p_true"] - arr["p_des"][:, :3], axis=1)
        moved = data.state.value
        y0, t0 = cl.plant.position[1], cl.net.time
        cl.run(5.0, each=ramped_force(t0, force))
        arr = cl.arrays()
        dy = arr["p_true"][arr["t"] >= t0, 1] - y0
        return {
            "rms": 1e3 * float(np.sqrt(np.mean(err**2))),
            "max": 1e3 * float(err.max()),
            "moves": moved,
            "peak": 1e3 * float(np.max(np.abs(dy))),
            "left": 1e3 * float(abs(dy[-1])),
            "state": data.state.value + (f" ({data.fault_reason})" if data.fault_reason else ""),
        }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--configs", default="config/rowc.toml,config/rowc_odrive.toml")
    ap.add_argument("--rates", default="250,500", help="Hz, comma-separated")
    ap.add_argument("--force", type=float, default=30.0, help="N along y")
    args = ap.parse_args()
    logging.disable(logging.WARNING)
    print(f"| robot file | drives | rate | demo: RMS / max error | {args.force:g} N: peak, "
          "after 5 s | final state |")  # fmt: skip
    print("| --- | --- | --- | --- | --- | --- |")
    for name in args.configs.split(","):
        base = load_robot(ROOT / name)
        for rate in (float(r) for r in args.rates.split(",")):
            model = dataclasses.replace(base, control=dataclasses.replace(base.control, rate=rate))
            r = measure(model, args.force)
            print(f"| {Path(name).name} | {model.drives.driver} {model.drives.mode} | {rate:g} Hz "
                  f"| {r['rms']:.3f} / {r['max']:.3f} mm | {r['peak']:.2f} mm, {r['left']:.3f} "
                  f"mm | {r['state']} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
