"""The self-calibration over 20 seeded unknown starts (within 10 cm and 5° of home, inside the
workspace box) on rowc and CAROCA, in lock-step: the calibrated estimate against the plant's
truth, with and without plant errors (anchors ±5 mm, drum radii ±0.5 %). Writes the markdown
table that docs/homing.md quotes.

    .venv/bin/python tools/homing_table.py [--seeds 20] [--out docs/homing_table.md]
"""

from __future__ import annotations

import numpy as np
from _tables import ROOT, markdown_head, table_options, write_table  # test_homing: on the path
from test_homing import pose_error, robot_at, start_pose

from cdprctl.calibration.procedure import self_calibrate
from cdprctl.calibration.session import CalibrationFailedError
from cdprctl.robot_file import load_robot
from sim_backend.plant_errors import PlantErrors


def run(robot: str, seeds: int, errors: bool) -> list[str]:
    model = load_robot(ROOT / "config" / f"{robot}.toml")
    pos: list[float] = []
    rot: list[float] = []
    pos_refused: list[float] = []
    rot_refused: list[float] = []
    sig: list[np.ndarray] = []
    refused = stopped = 0
    for seed in range(1, seeds + 1):
        p, R = start_pose(model, seed)
        plant_model = PlantErrors(seed).apply(model)[0] if errors else None
        with robot_at(model, p, R, plant_model) as ls:
            ls.driver.configure()
            try:
                rec, _ = self_calibrate(model, ls.driver, log=lambda s: None)
                kept = True
            except CalibrationFailedError as exc:
                refused += 1
                print(f"{robot} seed {seed} errors={errors}: refused: {exc}", flush=True)
                if exc.record is None:  # stopped before identifying: nothing to compare
                    stopped += 1
                    continue
                rec, kept = exc.record, False
            dp, dr = pose_error(model, rec, ls)
        (pos if kept else pos_refused).append(dp)
        (rot if kept else rot_refused).append(dr)
        if kept:
            sig.append(np.array(rec.std) * 1e3)
        print(f"{robot} seed {seed} errors={errors}: {dp:.3f} mm {dr:.3f} mrad"
              + ("" if kept else " (refused)"), flush=True)  # fmt: skip

    def stats(values: list[float]) -> str:
        return f"{np.median(values):.2f} / {max(values):.2f}" if values else "–"

    s = np.array(sig).reshape(-1, 6)
    sigma = (f"{np.median(s[:, :3].max(axis=1)):.2f} / {np.median(s[:, 3:].max(axis=1)):.2f}"
             if len(s) else "–")  # fmt: skip
    return [
        f"| {robot} | {'±5 mm, ±0.5 %' if errors else 'none'} | {len(pos)}/{seeds} "
        f"({refused - stopped} refused by the identification, {stopped} without a result: stopped "
        f"on a tension or not converged) "
        f"| {stats(pos)} | {stats(rot)} | {sigma} | {stats(pos_refused)} / "
        f"{stats(rot_refused)} |"
    ]


def main() -> None:
    ap = table_options("homing_table.md", seeds=20)
    args = ap.parse_args()
    lines = markdown_head(
        "| robot | plant errors | calibrated | position error mm, median / max | rotation "
        "error mrad, median / max | predicted σ, worst axis, median: mm / mrad | the refused "
        "ones' errors: mm, mrad (median / max) |"
    )
    for robot in ("rowc", "caroca"):
        for errors in (False, True):
            lines += run(robot, args.seeds, errors)
    write_table(args.out, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
