"""``cdprctl check-config FILE``: validate a robot description and summarise it."""

from __future__ import annotations

import math
import sys
from typing import Any

import numpy as np

from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model import ConfigError, RobotModel
from cdprctl.robot_file import load_robot


def safety_summary(model: RobotModel) -> str:
    """``[safety]``: the brake test's rule and the stop categories that differ from their
    defaults (docs/safety.md)."""
    from cdprctl.model.safety import STOP_CATEGORIES, stop_key

    sf = model.safety
    torque = (f"{sf.brake_test_torque:g} N·m" if sf.brake_test_torque is not None
              else f"{sf.brake_test_torque_factor:g} x the worst-case load")  # fmt: skip
    changed = [f"{stop_key(k)} {c}" for k, c in sf.stop_category.items()
               if c != STOP_CATEGORIES[k][0][0]]  # fmt: skip
    return (f"safety      brake test every {sf.brake_test_interval / 3600.0:g} h at {torque}, "
            f"at most {sf.brake_test_max_counts} counts; stop categories: "
            + (", ".join(changed) if changed else "the defaults"))  # fmt: skip


def ros2_summary(model: RobotModel) -> str:
    """The ROS 2 link's line: on or off, domain (or why the environment's is none), topics."""
    r = model.ros2
    domain = r.environment_problem() or f"domain {r.domain()}"
    state = "on" if r.enabled else "off (cdprctl run --ros2 turns it on)"
    return (f"ros2        {state}; {domain}, topics under /{r.topic_namespace(model.name)} at "
            f"{r.rate:g} Hz (docs/ros2.md)")


#: points per axis of the workspace box the clearance is measured over
CLEARANCE_GRID = 11
#: the rotations of the box's points: ``max_angle`` about the base's ±x, ±y, ±z
TURNS = ("+x", "-x", "+y", "-y", "+z", "-z")


def clearance_summary(model: RobotModel) -> tuple[str, list[str]]:
    """The cables' least distance (``[interference]``, docs/clearance.md) at the home pose,
    over the workspace box at the home orientation (``CLEARANCE_GRID`` points per axis) and
    over the box turned ``max_angle`` about each of ``TURNS``, each with its pair and where,
    against the limit; and a warning for each under the limit (a robot under it at home may
    move only where its cables get no closer; the box's poses under it the soft limits
    refuse: docs/clearance.md)."""
    from cdprctl.geometry.interference import distance_words
    from cdprctl.motion.clearance import Clearance

    c = Clearance(model)
    if not c.active:
        return "clearance   nothing to check (one cable, no body, no obstacle)", []
    limit = f"the [interference] clearance {c.limit * 1e3:.2f} mm"
    home = np.r_[model.home.position, 0.0, 0.0, 0.0]
    d_home, pair = c.closest_at(home)  # no slack here: the least pair, its distance
    under = " UNDER the limit" if d_home < c.limit else ""
    words = [f"at home {distance_words(d_home, apart='')} ({pair}){under}"]
    warnings = []
    if d_home < c.limit:
        warnings.append(
            f"at the home pose {pair} are {distance_words(d_home)}, under "
            f"{limit}: from home the robot may move only where they get no closer "
            "(docs/clearance.md)"
        )
    for name, coords in _box_poses(model):
        dist, _ = c.at(coords)
        j = int(np.argmin(dist))
        where = f"at {np.round(coords[j, :3], 4).tolist()} m"
        if np.any(coords[j, 3:]):
            where += f" turned about {TURNS[j * len(TURNS) // len(coords)]}"
        under = " UNDER the limit" if dist[j] < c.limit else ""
        pair = c.pair_at(coords[j])
        words.append(f"over the workspace box {name} {distance_words(dist[j], apart='')} "
                     f"({pair} {where}){under}")  # fmt: skip
        if n_under := int(np.count_nonzero(dist < c.limit)):
            warnings.append(
                f"{n_under} of {len(coords)} poses of the [workspace] box {name} are under "
                f"{limit} (least {distance_words(dist[j], apart='')}, {pair} {where}): the "
                "soft limits refuse them, so the robot cannot reach all of its stated "
                "workspace (docs/clearance.md)"
            )
    return (f"clearance   limit {c.limit * 1e3:.2f} mm ([interference] clearance); "
            + "; ".join(words) + f" ({CLEARANCE_GRID} points per axis; docs/clearance.md)"
            ), warnings  # fmt: skip


def _box_poses(model: RobotModel) -> list[tuple[str, np.ndarray]]:
    """The workspace box's grid as trajectory coordinates (m, rad from home): at the home
    orientation, and turned ``max_angle`` about each of ``TURNS`` (in that order)."""
    ws = model.workspace
    axes = [np.linspace(ws.position_min[k], ws.position_max[k], CLEARANCE_GRID) for k in range(3)]
    box = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    out = [("at the home orientation", np.c_[box, np.zeros((len(box), 3))])]
    if ws.max_angle > 0.0:
        turns = [np.eye(3)[k] * sign * ws.max_angle for k in range(3) for sign in (1.0, -1.0)]
        out.append((f"turned {ws.max_angle:g} rad", np.vstack([np.c_[box, np.tile(t, (len(box), 1))]
                                                               for t in turns])))  # fmt: skip
    return out


def cell_summary(model: RobotModel) -> list[str]:
    """The platform's body and the cell's obstacles as read, each by its name and its table
    (the messages name a shape by its name; a file error by its table, counted from 0)."""
    from cdprctl.model.interference import Box

    def vec(v: Any) -> str:
        return str(np.round(np.asarray(v, dtype=float), 4).tolist())

    cfg = model.interference
    body = [f"platform.body.boxes[{k}] {b.name!r}: centre {vec(b.centre)} m, half extents "
            f"{vec(b.half_extents)} m" for k, b in enumerate(cfg.body)]  # fmt: skip
    cell = [f"cell.obstacles[{k}] {o.name!r}: " + (
        f"box, centre {vec(o.centre)} m, half extents {vec(o.half_extents)} m"
        if isinstance(o, Box) else f"plane through {vec(o.point)} m, normal {vec(o.normal)}")
        for k, o in enumerate(cfg.obstacles)]  # fmt: skip
    return [f"body        {'; '.join(body) or 'none given ([[platform.body.boxes]])'}",
            f"cell        {'; '.join(cell) or 'no obstacle given ([[cell.obstacles]])'}"]


def verdict(file: str, warnings: list[str]) -> list[str]:
    """The summary's first line and its warnings: ``OK`` only with none."""
    if not warnings:
        return [f"{file}: OK"]
    n = len(warnings)
    return [f"{file}: valid, with {n} warning{'s' if n != 1 else ''}"] + [
        f"  warning: {w}" for w in warnings
    ]


def summary(model: RobotModel) -> tuple[str, list[str]]:
    """What ``check-config`` prints of ``model``, and its warnings (the first line says they
    are there, each under it)."""
    home = model.home
    data = KinematicsData(model)
    inverse_kinematics(model, data, home.position, home.rotation)
    k = model.cable_stiffness(data.length)
    pf = model.platform
    rpy_deg = ", ".join(f"{math.degrees(a):.2f}" for a in home.rpy)
    clearance, warnings = clearance_summary(model)
    lines = [
        *verdict(str(model.source_file), warnings),
        f"robot       {model.name}  ({model.source})",
        f"cables      {model.n_cables} (redundancy r = {model.redundancy})"
        + (", swivel pulleys" if model.has_pulleys else ""),
        f"platform    mass {pf.mass:g} kg, COM {np.round(pf.com, 4).tolist()} m, "
        f"inertia diag {np.round(np.diag(pf.inertia), 4).tolist()} kg·m²",
        f"gravity     {model.gravity.tolist()} m/s²",
        f"home        position {home.position.tolist()} m, rpy [{rpy_deg}] deg",
        clearance,
        *cell_summary(model),
        safety_summary(model),
        ros2_summary(model),
        "",
        f"{'cable':>6} {'t_min N':>9} {'t_max N':>9} {'length m':>9} {'k N/m':>10} "
        f"{'winch max N':>11}",
    ]
    for i, c in enumerate(model.cables):
        lines.append(
            f"{c.name:>6} {c.tension_min:9.1f} {c.tension_max:9.1f} {data.length[i]:9.4f} "
            f"{k[i]:10.4g} {c.winch.max_cable_force:11.1f}"
        )
    for g in model.grippers:
        obj = "rigid" if math.isinf(g.object_stiffness) else f"{g.object_stiffness:g} N/m"
        lines.append(
            f"gripper on cable {g.name}: jaw {g.jaw_mass:g} kg, K_A {k[g.cable]:g} N/m, "
            f"K_B {g.k_b:g} N/m, L21 {g.free_travel:g} m (object {obj}), guide "
            f"0-{g.travel_max:g} m, friction {g.guide_friction:g} N"
        )
    return "\n".join(lines), warnings


def run(file: str, strict: bool = False) -> int:
    """0 the file is usable (with warnings or none), 1 it has errors ``cdprctl run`` would
    refuse, or warnings under ``strict``."""
    try:
        model = load_robot(file)
    except ConfigError as exc:
        n = len(exc.errors)
        print(f"{file}: {n} error{'s' if n != 1 else ''}:", file=sys.stderr)
        for e in exc.errors:
            print(f"  {e}", file=sys.stderr)
        return 1
    text, warnings = summary(model)
    print(text)
    from cdprctl.telemetry.zenoh.security import command_security_problems
    from cdprctl.telemetry.zenoh.zenoh_files import missing_files

    problems = missing_files(model.zenoh.config_file) + command_security_problems(model.zenoh)
    for p in problems:  # cdprctl run would refuse to start with these
        print(f"{file}: {p}", file=sys.stderr)
    if strict and warnings and not problems:
        n = len(warnings)
        print(f"{file}: {n} warning{'s' if n != 1 else ''} (above) and --strict: exit 1",
              file=sys.stderr)  # fmt: skip
    return 1 if problems or (strict and warnings) else 0
