"""Checks of an assembled robot description that need its geometry."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel


def check_model(model: RobotModel) -> list[str]:
    """Errors of ``model`` at its home pose (empty when it is usable)."""
    f = model.source_file
    errors: list[str] = []
    ws, home = model.workspace, model.home
    pos = home.position
    for k, axis in enumerate("xyz"):
        if not ws.position_min[k] <= pos[k] <= ws.position_max[k]:
            errors.append(
                f"{f}: home.position[{k}] = {pos[k]:g} m is outside the workspace "
                f"[{ws.position_min[k]:g}, {ws.position_max[k]:g}] m ({axis})"
            )
    data = KinematicsData(model)
    inverse_kinematics(model, data, pos, home.rotation)
    for i, c in enumerate(model.cables):
        r = c.pulley.radius if c.pulley else 0.0
        if not np.isfinite(data.free_length[i]) or data.free_length[i] <= max(r, 1e-3):
            errors.append(
                f"{f}: cables[{i}] has a free length of {data.free_length[i]:.4g} m at the home "
                "pose: the attachment must be farther than the pulley radius (and 1 mm) from "
                "the exit point"
            )
    if errors:
        return errors
    rank = int(np.linalg.matrix_rank(data.W, tol=1e-9 * max(1.0, float(np.abs(data.W).max()))))
    if rank < 6:
        errors.append(
            f"{f}: home pose: the wrench matrix has rank {rank} < 6: the cables cannot hold "
            "the platform in every direction there (check anchors and attachments)"
        )
        return errors
    w_ext = model.gravity_wrench(home.rotation)
    t = feasible_tensions_lp(data.W, w_ext, model.tension_min, model.tension_max)
    if t is None:
        errors.append(
            f"{f}: home pose: no tensions within [tension_min, tension_max] hold the platform's "
            f"weight ({model.platform.mass:g} kg): the home pose is not wrench-feasible"
        )
    return errors


def feasible_tensions_lp(
    W: FloatArray, w_ext: FloatArray, t_min: FloatArray, t_max: FloatArray
) -> FloatArray | None:
    """Tensions with ``W t + w_ext = 0`` inside the bounds that maximise the smallest margin
    to them (an LP), or ``None`` when there are none. For checks outside the loop."""
    m = W.shape[1]
    # Variables [t (m), s]; maximise s subject to t_min + s <= t <= t_max - s.
    c = np.zeros(m + 1)
    c[-1] = -1.0
    A_eq = np.hstack([W, np.zeros((6, 1))])
    eye = np.eye(m)
    ones = np.ones((m, 1))
    A_ub = np.vstack([np.hstack([-eye, ones]), np.hstack([eye, ones])])
    b_ub = np.concatenate([-t_min, t_max])
    res = linprog(
        c,
        A_ub=A_ub,
        b_ub=b_ub,
        A_eq=A_eq,
        b_eq=-w_ext,
        bounds=[(None, None)] * m + [(0.0, None)],
        method="highs",
    )
    if res.status != 0:
        return None
    return np.asarray(res.x[:m])
