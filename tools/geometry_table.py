"""The geometric calibration over seeded as-built robots, in lock-step: each robot's non-
reference anchors off by up to ±20 mm per axis and its drums by up to ±1 %, the start within
5 cm / 3° of home, incremental encoders. Measured against the plant's truth: the anchors and
drums identified, and the platform's pose by the calibrated robot file and its record at 10
test poses across the workspace (the plant set there; the estimator's forward kinematics).
Writes the markdown table that docs/homing.md quotes.

    .venv/bin/python tools/geometry_table.py [--seeds 5] [--robots rowc caroca cogiro]
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np
from _tables import ROOT, markdown_head, table_options, write_table  # test_homing: on the path
from test_homing import robot_at

from cdprctl.calibration.geometry_file import calibrated_robot_text
from cdprctl.calibration.geometry_moves import motor_goals, move
from cdprctl.calibration.geometry_plan import GeometryOptions
from cdprctl.calibration.geometry_procedure import (
    geometry_calibrate,
    geometry_record,
)
from cdprctl.calibration.procedure import force_cables
from cdprctl.calibration.session import CalibrationFailedError, Session
from cdprctl.calibration.startup_checks import offsets
from cdprctl.control.cycle.estimator import Estimator
from cdprctl.core.rotation import exp_so3, log_so3
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.calibration import reference_anchors
from cdprctl.robot_file import load_robot
from cdprctl.tda.hold import equilibrium_tensions
from sim_backend.plant_errors import PlantErrors


def start_near_home(model, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A seeded start within 5 cm and 3° of home."""
    rng = np.random.default_rng(1000 + seed)
    d = rng.normal(size=3)
    d *= rng.uniform(0.0, 0.05) / np.linalg.norm(d)
    a = rng.normal(size=3)
    a *= rng.uniform(0.0, np.radians(3.0)) / np.linalg.norm(a)
    return np.asarray(model.home.position, float) + d, exp_so3(a) @ model.home.rotation


def test_poses(model, seed: int, n: int = 10) -> list[tuple[np.ndarray, np.ndarray]]:
    """``n`` poses inside 70 % of the workspace box, tilted up to half its angle, held."""
    rng = np.random.default_rng(2000 + seed)
    ws = model.workspace
    lo, hi = np.asarray(ws.position_min), np.asarray(ws.position_max)
    kin = KinematicsData(model)
    out: list[tuple[np.ndarray, np.ndarray]] = []
    while len(out) < n:
        p = lo + (0.15 + 0.7 * rng.uniform(size=3)) * (hi - lo)
        a = rng.normal(size=3)
        a *= rng.uniform(0.0, 0.5 * ws.max_angle) / np.linalg.norm(a)
        R = exp_so3(a) @ model.home.rotation
        inverse_kinematics(model, kin, p, R)
        t = equilibrium_tensions(model, kin)
        if np.all(t > model.tension_min + 1.0) and np.all(t < model.tension_max - 1.0):
            out.append((p, R))
    return out


def estimate(built, record, theta: np.ndarray, tension: np.ndarray,
             near: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The estimator's pose with the calibrated file and record from the encoders and
    tensions, started 35 mm off (the loop tracks the platform: the forward kinematics'
    accuracy, not its basin)."""
    e = Estimator(built)
    e.apply_calibration(*offsets(record))
    e.reset(near + np.array([0.02, -0.02, 0.02]), R)
    for k in range(60):
        e.update(0.01 * k, theta, tension)
    return e.position.copy(), e.rotation.copy()


def visit(built, record, ls, targets) -> tuple[list[float], list[float]]:
    """The platform moved by the calibrated file to each target (six cables by position, the
    redundant ones by tension, as the calibration moves), and at rest there the estimator's
    pose against the plant's: mm and mrad per target."""
    ses = Session(built, ls.driver, lambda s: None)
    kin = KinematicsData(built)
    theta_zero = np.asarray(record.theta_zero)
    inverse_kinematics(built, kin, built.home.position, built.home.rotation)
    l_home = kin.length.copy()
    ses.force[force_cables(built)] = True
    ses.k[:] = built.cable_stiffness(l_home)
    ses.gain = 1.0 - math.exp(-2.0 * math.pi * 2.0 * ls.driver.period)

    goal_of = motor_goals(built, theta_zero, l_home, ses.ratio)
    start = np.r_[record.pose[:3], np.zeros(3)]
    _, t = goal_of(start)
    ses.tension_goal[:] = t
    err_p, err_r = [], []
    opt = GeometryOptions.of(built)
    try:
        ses.enable()
        ses.run(1.0)
        here = start
        for p, R in targets:
            x = np.r_[p, log_so3(R @ built.home.rotation.T)]
            done, _ = move(ses, here, x, goal_of, opt)
            here = here + done * (x - here)
            ses.run(1.0)
            theta, tension, _ = ses.average(0.3)
            ep, eR = estimate(built, record, theta, tension, ls.plant.position, ls.plant.R)
            err_p.append(float(np.linalg.norm(ep - ls.plant.position) * 1e3))
            err_r.append(float(np.linalg.norm(log_so3(eR @ ls.plant.R.T)) * 1e3))
        move(ses, here, start, goal_of, opt)
    finally:
        ses.close()
    return err_p, err_r


def run(robot: str, seed: int, poses: int) -> dict:
    model = load_robot(ROOT / "config" / f"{robot}.toml")
    ref = reference_anchors(model.calibration, model.anchors)
    truth = PlantErrors(seed, 0.02, 0.01, tuple(ref)).apply(model)[0]
    p, R = start_near_home(model, seed)
    t0 = time.monotonic()
    row: dict = {"robot": robot, "seed": seed}
    with robot_at(model, p, R, truth) as ls:
        ls.driver.configure()
        try:
            cal = geometry_calibrate(model, ls.driver, GeometryOptions.of(model, poses=poses),
                                     log=lambda s: None)  # fmt: skip
        except CalibrationFailedError as exc:
            row.update(stopped=str(exc), wall=time.monotonic() - t0)
            return row
        r = cal.result
        true_a = np.array([c.anchor for c in truth.cables])
        true_s = np.array([c.winch.drum_radius for c in truth.cables]) / np.array(
            [c.winch.drum_radius for c in model.cables])
        radius = np.array([c.winch.drum_radius for c in model.cables]) * r.drum_scale
        with tempfile.TemporaryDirectory() as d:
            f = Path(d) / "built.toml"
            f.write_text(calibrated_robot_text(model, r.anchors, radius, "table"))
            built = load_robot(f)
        record = geometry_record(built, cal, [None] * model.n_cables)
        err_p, err_r = visit(built, record, ls, test_poses(model, seed))
        a_err = np.linalg.norm(r.anchors - true_a, axis=1) * 1e3
        a_sig = np.linalg.norm(r.std_anchors, axis=1) * 1e3
        free = [i for i in range(model.n_cables) if i not in ref]
        row.update(
            accepted=cal.accepted, reason=cal.reason, motion=cal.motion_time,
            anchor_max=float(a_err.max()), anchor_sigma=float(a_sig[free].max()),
            anchor_z=float(np.max(a_err[free] / np.maximum(a_sig[free], 1e-9))),
            drum_max=float(np.max(np.abs(r.drum_scale - true_s)) * 100),
            pose_med=float(np.median(err_p)), pose_max=float(np.max(err_p)),
            rot_med=float(np.median(err_r)), rot_max=float(np.max(err_r)),
            ratio=cal.residuals_over_noise, balance=cal.equilibrium_over_noise,
            wall=time.monotonic() - t0,
        )  # fmt: skip
    return row


def main() -> None:
    ap = table_options("geometry_table.md", seeds=5)
    ap.add_argument("--first", type=int, default=1,
                    help="the first seed (a table split over processes)")
    ap.add_argument("--poses", type=int, default=25)
    ap.add_argument("--robots", nargs="+", default=["rowc", "caroca", "cogiro"])
    args = ap.parse_args()
    lines = markdown_head(
        "| robot | accepted | anchors: error, max mm (worst σ mm; worst error/σ) | drums: "
        "error, max % | pose at 10 test poses, median / max: mm, mrad | motion s | "
        "residuals / noise: lengths; equilibrium |"
    )
    for robot in args.robots:
        rows = []
        for seed in range(args.first, args.first + args.seeds):
            row = run(robot, seed, args.poses)
            rows.append(row)
            print(row, flush=True)
        done = [r for r in rows if "stopped" not in r]
        acc = [r for r in done if r["accepted"]]

        def rng(key: str, rs: list[dict], fmt: str = ".2f") -> str:
            v = [r[key] for r in rs]
            return f"{min(v):{fmt}}-{max(v):{fmt}}" if v else "–"

        lines.append(
            f"| {robot} | {len(acc)}/{len(rows)} ({len(rows) - len(done)} stopped) | "
            f"{rng('anchor_max', done)} ({rng('anchor_sigma', done)}; {rng('anchor_z', done)}) | "
            f"{rng('drum_max', done, '.3f')} | {rng('pose_med', done)} / {rng('pose_max', done)}"
            f" mm, {rng('rot_med', done)} / {rng('rot_max', done)} mrad | "
            f"{rng('motion', done, '.0f')} | {rng('ratio', done)}; {rng('balance', done)} |"
        )
    write_table(args.out, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
