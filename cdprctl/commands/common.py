"""What the commands share."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from cdprctl.commands.parsing import command_parser as command_parser  # re-exported
from cdprctl.core.angles import user_angles
from cdprctl.model import ConfigError, RobotModel
from cdprctl.robot_file import load_robot


def os_error_text(exc: Exception) -> str:
    """An OS error as a user reads it ("No such file or directory"), not its errno repr."""
    return str(exc.strerror) if isinstance(exc, OSError) and exc.strerror else str(exc)


def load_or_report(path: str, who: str = "") -> RobotModel | None:
    """The robot of ``path``, or None after printing every error of the file to stderr
    (``who``: the command, before each line, as its other errors have it)."""
    try:
        return load_robot(path)
    except ConfigError as exc:
        for e in exc.errors:
            print(f"{who}: {e}" if who else e, file=sys.stderr)
        return None


def pose_or_why(text: str) -> np.ndarray | str:
    """``x,y,z,roll,pitch,yaw`` (m, then rad or each angle ending in deg: ``core.angles``' rule,
    a bare angle beyond pi refused as degrees typed for radians) → 6 values (m, rad); else why
    not, in words."""
    parts = text.split(",")
    try:
        position = [float(v) for v in parts[:3]]
    except ValueError:
        position = []
    if len(parts) != 6 or len(position) != 3 or not all(np.isfinite(position)):
        return "expected six finite numbers x,y,z,roll,pitch,yaw (m, then rad or deg)"
    angles = user_angles(parts[3:])
    return angles if isinstance(angles, str) else np.array([*position, *angles])


def parse_pose(text: str, what: str, model: Any = None) -> np.ndarray:
    """``x,y,z,roll,pitch,yaw`` (``pose_or_why``) → array (m, rad); SystemExit naming the rule
    otherwise, and, given the ``model``, for a position outside its workspace box (where no
    file of it promises the cables can hold the platform)."""
    values = pose_or_why(text)
    if isinstance(values, str):
        raise SystemExit(f"{what} = {text!r}: {values}")
    if model is not None:
        ws = model.workspace
        for k, axis in enumerate("xyz"):
            if not ws.position_min[k] <= values[k] <= ws.position_max[k]:
                raise SystemExit(
                    f"{what}: {axis} = {values[k]:g} m is outside the workspace box "
                    f"[{ws.position_min[k]:g}, {ws.position_max[k]:g}] m ([workspace] of "
                    f"{model.source_file})"
                )
    return values
