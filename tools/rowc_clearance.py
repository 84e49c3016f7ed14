"""rowc's crossed pairs (1-2, 3-4, 5-6, 7-8): the search that chose the offsets rowc.toml ships
with (issue 67). From the geometry before them (each pair's anchors at the frame's corner, its
attachments at the body's corner: the two cables in one plane, through each other), offsets of
one cable of each pair, each checked against the property rowc.toml documents: the 50 N
lateral force (+y) held over the workspace.

* The workspace as rowc.toml documents it: the ``[workspace]`` box at the home orientation
  (the file scanned the 50 N force "every 0.2 m x 0.1 m"); here every 25 mm in x and z and
  10 mm in y. Then the same box with the platform tilted up to ``max_angle`` (0.2 rad) about
  26 axes (the cube's faces, edges and corners) plus 200 random rotations, every 0.1 m.
* Clearance: ``cdprctl/geometry/interference.py`` on every pose; the least pose of each variant
checked
  again by scipy's bounded least squares (BVLS) on the segments, apart from the kernel (the
  shipped geometry's full grid by brute force: ``tools/clearance_check.py``, docs/clearance.md).
* Feasible: ``cdprctl.tda.workspace.Margins`` (the tension margin of ``cdprctl workspace``)
  holding the weight and w_e = [0, 50, 0, 0, 0, 0] at the home orientation, on the file's
  scan (x every 0.2 m, z every 0.1 m, in the platform's plane y = 0.35 m: the force is not
  held at y < 0.35 m) and on the fine grid of the whole box.

The variants move the even cable of each pair (2, 4, 6, 8: the back anchor, the front
attachment) by ``d`` in x towards the frame's middle (+x for the pairs at x = 0, −x at x = 3):
its attachment (along the body's edge), its anchor (along the frame's beam), or both.

    .venv/bin/python tools/rowc_clearance.py [--offsets 0.02 0.04 0.06 ...]
"""

from __future__ import annotations

import argparse
import copy
import itertools
import math
from pathlib import Path

import numpy as np
from scipy.optimize import lsq_linear

from cdprctl.core.rotation import exp_so3
from cdprctl.geometry.interference import BODY, CABLE, Interference
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model import RobotModel
from cdprctl.robot_file import parse_robot
from cdprctl.robot_file.loader import read_merged
from cdprctl.tda.workspace import Margins, hold_wrench

ROOT = Path(__file__).resolve().parents[1]
PAIRS = ((0, 1), (2, 3), (4, 5), (6, 7))
LATERAL = np.array([0.0, 50.0, 0.0, 0.0, 0.0, 0.0])  # N: ARK 2020's force, rowc.toml


def variant(where: str, d: float, axis: int = 0) -> tuple[RobotModel, dict]:
    """rowc with the even cable of each pair moved ``d`` (m) along ``axis`` (0: x, 2: z)
    towards the middle (of the frame for an anchor, of the body for an attachment) at
    ``where`` ("attachment", "anchor", "both"); the TOML as edited."""
    data = before_offsets(copy.deepcopy(read_merged(ROOT / "config" / "rowc.toml")))
    middle = 1.5 if axis == 0 else 0.7  # m: the frame's middle in x, in z
    for _, j in PAIRS:
        cable = data["cables"][j]
        if where in ("attachment", "both"):
            inward = d if cable["attachment"][axis] < 0.0 else -d
            if axis == 0:  # the pair moves as one: its anchor's side, not its attachment's
                inward = d if cable["anchor"][0] < middle else -d
            cable["attachment"][axis] = round(cable["attachment"][axis] + inward, 6)
        if where in ("anchor", "both"):
            inward = d if cable["anchor"][axis] < middle else -d
            cable["anchor"][axis] = round(cable["anchor"][axis] + inward, 6)
    return parse_robot(data, f"rowc ({where} {d * 1e3:g} mm)"), data


def before_offsets(data: dict) -> dict:
    """rowc's cables as they were before issue 67: every anchor at the frame's corner (x 0 or
    3 m, z 0 or 1.4 m), every attachment at the body's corner (x and z ±0.1 m)."""
    for cable in data["cables"]:
        a, b = cable["anchor"], cable["attachment"]
        a[0], a[2] = (0.0 if a[0] < 1.5 else 3.0), (0.0 if a[2] < 0.7 else 1.4)
        b[0], b[2] = math.copysign(0.1, b[0]), math.copysign(0.1, b[2])
    return data


def box_grid(model: RobotModel, dx: float, dy: float, dz: float) -> np.ndarray:
    lo, hi = model.workspace.position_min, model.workspace.position_max
    axes = [np.linspace(lo[k], hi[k], round((hi[k] - lo[k]) / s) + 1)
            for k, s in enumerate((dx, dy, dz))]  # fmt: skip
    return np.array(list(itertools.product(*axes)))


def tilts(angle: float, n_random: int, seed: int = 0) -> list[np.ndarray]:
    dirs = [np.array(v, float) for v in itertools.product((-1, 0, 1), repeat=3) if any(v)]
    rng = np.random.default_rng(seed)
    dirs += list(rng.normal(size=(n_random, 3)))
    out = [np.eye(3)]
    for v in dirs:
        v = v / np.linalg.norm(v)
        out.append(exp_so3(v * angle * (1.0 if len(out) <= 26 else rng.uniform(0.5, 1.0))))
    return out


def least(model: RobotModel, poses: list[tuple[np.ndarray, np.ndarray]]) -> dict:
    """The least distance of the crossed pairs, of every pair of cables, and of the cables
    and the body, with the pose of each."""
    kin = KinematicsData(model)
    check = Interference(model)
    pair_rows = [c for c, (kind, i, j, *_) in enumerate(check.checks)
                 if kind == CABLE and (int(i), int(j)) in PAIRS]  # fmt: skip
    cable_rows = [c for c, row in enumerate(check.checks) if row[0] == CABLE]
    body_rows = [c for c, row in enumerate(check.checks) if row[0] == BODY]  # rowc: no cell
    out = {k: (np.inf, None, "") for k in ("crossed", "cables", "body")}
    for p, R in poses:
        inverse_kinematics(model, kin, p, R)
        check.update(kin)
        for key, rows in (("crossed", pair_rows), ("cables", cable_rows), ("body", body_rows)):
            c = rows[int(np.argmin(check.distance[rows]))]
            if check.distance[c] < out[key][0]:
                out[key] = (float(check.distance[c]), (p, R), check.describe(c))
    return out


def bvls_pair(model: RobotModel, pose: tuple[np.ndarray, np.ndarray]) -> float:
    """The crossed pairs' least distance at ``pose`` by scipy's BVLS, apart from the kernel."""
    p, R = pose
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, p, R)
    B = p + model.attachments @ R.T
    E = kin.exit_points
    best = np.inf
    for i, j in PAIRS:
        A = np.column_stack([E[i] - B[i], -(E[j] - B[j])])
        x = lsq_linear(A, B[j] - B[i], bounds=(0.0, 1.0), method="bvls").x
        best = min(best, float(np.linalg.norm(B[i] + x[0] * (E[i] - B[i]) - B[j]
                                              - x[1] * (E[j] - B[j]))))  # fmt: skip
    return best


def margins(model: RobotModel, points: np.ndarray) -> np.ndarray:
    R = model.home.rotation
    w = hold_wrench(model, R, LATERAL)
    n = len(points)
    return Margins(model).of(points, np.broadcast_to(R, (n, 3, 3)), np.broadcast_to(w, (n, 6)))


def report(model: RobotModel, label: str, fine, tilted, scan) -> str:
    home = least(model, [(model.home.position, model.home.rotation)])
    flat = least(model, [(p, model.home.rotation) for p in fine])
    tilt = least(model, tilted)
    m_scan, m_fine = margins(model, scan), margins(model, fine)
    check = bvls_pair(model, flat["crossed"][1]) if flat["crossed"][1] else np.nan
    return (
        f"| {label} | {home['crossed'][0] * 1e3:.2f} | {flat['crossed'][0] * 1e3:.2f} "
        f"(BVLS {check * 1e3:.2f}) | {tilt['crossed'][0] * 1e3:.2f} | "
        f"{flat['body'][0] * 1e3:.1f} ({flat['body'][2].split(':')[0]}) | "
        f"{m_scan.min():.1f} | {m_fine.min():.1f} ({int((m_fine >= 0).sum())}/{len(m_fine)}) |"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--offsets", type=float, nargs="*", default=[0.03, 0.06, 0.065, 0.09, 0.12])
    ap.add_argument("--where", nargs="*", default=["attachment", "anchor", "both"])
    ap.add_argument("--axis", choices=("x", "z"), default="x")
    args = ap.parse_args()
    base, _ = variant("anchor", 0.0)
    fine = box_grid(base, 0.025, 0.01, 0.025)
    coarse = box_grid(base, 0.1, 0.035, 0.1)
    scan = np.array([p for p in box_grid(base, 0.2, 0.01, 0.1)
                     if abs(p[1] - base.home.position[1]) < 1e-9])  # fmt: skip
    rotations = tilts(base.workspace.max_angle, 200)
    tilted = [(p, R @ base.home.rotation) for p in coarse for R in rotations]
    print(
        f"{len(fine)} poses at home orientation, {len(tilted)} tilted (<= "
        f"{base.workspace.max_angle} rad), feasibility scan {len(scan)} points"
    )
    print(
        "| variant | crossed pairs at home (mm) | over the workspace, home orientation (mm) "
        "| tilted <= max_angle (mm) | cables-body, home orientation (mm) | 50 N margin, "
        "file's scan (N) | 50 N margin, fine grid (N) (feasible/points) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    print(report(base, "rowc before the offsets", fine, tilted, scan), flush=True)
    shipped = parse_robot(read_merged(ROOT / "config" / "rowc.toml"), "rowc")
    print(report(shipped, "rowc as shipped (x, z, z: 50, 50, 20 mm)", fine, tilted, scan))
    for where in args.where:
        for d in args.offsets:
            model, _ = variant(where, d, "xyz".index(args.axis))
            label = f"{where} {d * 1e3:g} mm in {args.axis}"
            print(report(model, label, fine, tilted, scan), flush=True)


if __name__ == "__main__":
    main()
