"""``cdprctl calibrate friction`` over seeded simulated robots, in lock-step: each winch's
viscous and Coulomb friction 30-50 % off the robot file's (up or down, seeded), a Stribeck term
half the Coulomb one. Per seed the worst error of each identified term against the simulated
robot's, over the winches; the markdown table docs/friction.md quotes. ``--cells``: the robots
with a load cell on every cable (``config/<robot>_load_cells.toml``), each winch fitted on its
cable's measured tension (no projection).

    .venv/bin/python tools/friction_table.py [--seeds 10] [--robots rowc cogiro] [--cells]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from cdprctl.calibration.session import CalibrationFailedError  # noqa: E402
from cdprctl.experiments.friction_on_plant import friction_on_plant  # noqa: E402
from cdprctl.robot_file import load_robot  # noqa: E402
from sim_backend.plant_errors import PlantErrors  # noqa: E402


def run(robot: str, seed: int, cells: bool = False) -> dict:
    """One calibration on ``robot`` (with ``cells``: its load cells' file) whose winches are
    drawn from ``seed``: the worst errors (% of the simulated robot's term), the fits' σ at
    their largest (% of the term) and whether it was accepted."""
    model = load_robot(ROOT / "config" / f"{robot}{'_load_cells' if cells else ''}.toml")
    truth = PlantErrors(seed, 0.0, 0.0, friction=(0.3, 0.5), stribeck=0.5).apply(model)[0]
    t0 = time.monotonic()
    row: dict = {"robot": robot, "seed": seed}
    try:
        cal = friction_on_plant(model, truth)
    except CalibrationFailedError as exc:
        return {**row, "stopped": str(exc), "wall": time.monotonic() - t0}
    pairs = list(zip(cal.fits, [c.winch for c in truth.cables], strict=True))
    err = {
        "viscous": [f.viscous / x.viscous_friction - 1 for f, x in pairs],
        "coulomb": [f.coulomb / x.coulomb_friction - 1 for f, x in pairs],
        "stribeck": [f.stribeck / x.stribeck_friction - 1 for f, x in pairs],
    }
    row.update({k: float(np.max(np.abs(v)) * 100) for k, v in err.items()})
    row["sigma"] = 100 * max(max(f.std[0] / x.viscous_friction, f.std[1] / x.coulomb_friction)
                             for f, x in pairs)  # fmt: skip
    row["source"] = ", ".join(sorted({f.source for f in cal.fits}))
    row.update(accepted=cal.accepted, reason=cal.reason, motion=cal.motion_time,
               wall=time.monotonic() - t0)  # fmt: skip
    return row


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--robots", nargs="+", default=["rowc", "cogiro"])
    ap.add_argument("--cells", action="store_true",
                    help="the robots' load-cell files: each winch fitted on its cell")  # fmt: skip
    args = ap.parse_args()
    print("| robot | seed | fitted on | accepted | viscous, worst error % | Coulomb, worst % | "
          "Stribeck, worst % | largest σ % | motion s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for robot in args.robots:
        for seed in range(args.first, args.first + args.seeds):
            r = run(robot, seed, args.cells)
            if "stopped" in r:
                print(f"| {robot} | {seed} | | stopped: {r['stopped']} | | | | | |", flush=True)
                continue
            print(f"| {robot} | {seed} | {r['source']} | "
                  f"{'yes' if r['accepted'] else 'no: ' + r['reason']} "
                  f"| {r['viscous']:.1f} | {r['coulomb']:.1f} | {r['stribeck']:.1f} | "
                  f"{r['sigma']:.2f} | {r['motion']:.0f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
