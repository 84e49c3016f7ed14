"""The external-wrench estimate under the 30 N water jet on a simulated robot whose winches'
friction is 30-50 % off the file (``PlantErrors``, seeded, as ``calibrate friction --sim
--plant-errors`` draws it), lock-step, three ways: the controller with the file's friction, with
the friction ``calibrate friction`` identified from the torques (the record's terms, as ``run``
applies them), and with load cells on every cable (``config/<robot>_load_cells.toml``, its
friction identified on the cells). The run is ``cdprctl/experiments/load_cells.py``'s: the
force error's largest norm at rest under the jet and over a 0.3 m move under it (N).
docs/friction.md quotes the table.

    .venv/bin/python tools/friction_jet.py [--robots rowc cogiro] [--seeds 3]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

from cdprctl.calibration.friction_record import friction_entry  # noqa: E402
from cdprctl.experiments.friction_on_plant import friction_on_plant  # noqa: E402
from cdprctl.experiments.load_cells import jet_run  # noqa: E402
from cdprctl.model.robot import RobotModel  # noqa: E402
from cdprctl.robot_file import load_robot  # noqa: E402
from sim_backend.plant_errors import PlantErrors  # noqa: E402


def identified(model: RobotModel, truth: RobotModel) -> tuple[list[float], ...]:
    """(viscous, Coulomb, Stribeck, pulley μ) per winch as a friction calibration on the
    simulated ``truth`` records them (``friction_entry``: what ``run`` applies)."""
    cal = friction_on_plant(model, truth)
    if not cal.accepted:
        raise SystemExit(f"{model.name}: the friction calibration was refused: {cal.reason}")
    e = friction_entry(model, cal.fits, cal.motion_time, True)
    return e["viscous"], e["coulomb"], e["stribeck"], e["pulley"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["rowc", "cogiro"])
    ap.add_argument("--seeds", type=int, default=3, help="friction draws (seeds 1..N)")
    args = ap.parse_args()
    print(
        "| robot | seed | file's friction: at rest, moving N | identified: at rest, moving N "
        "| load cells: at rest, moving N |"
    )
    print("| --- | --- | --- | --- | --- |")
    for robot in args.robots:
        plain = load_robot(ROOT / "config" / f"{robot}.toml")
        cells = load_robot(ROOT / "config" / f"{robot}_load_cells.toml")
        for seed in range(1, args.seeds + 1):
            truth = PlantErrors(seed, 0.0, 0.0, friction=(0.3, 0.5), stribeck=0.5)
            t_plain, t_cells = truth.apply(plain)[0], truth.apply(cells)[0]
            runs = [jet_run(plain, None, t_plain),
                    jet_run(plain, None, t_plain, identified(plain, t_plain)),
                    jet_run(cells, None, t_cells, identified(cells, t_cells))]  # fmt: skip
            cols = " | ".join(f"{r.at_rest:.2f}, {r.moving:.2f}"
                              + ("" if r.state == "enabled" else f" ({r.state}: {r.fault})")
                              for r in runs)  # fmt: skip
            print(f"| {robot} | {seed} | {cols} |", flush=True)


if __name__ == "__main__":
    sys.exit(main())
