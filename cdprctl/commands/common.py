"""What the commands share."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from cdprctl.commands.parsing import command_parser as command_parser  # re-exported
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


def parse_pose(text: str, what: str, model: Any = None) -> np.ndarray:
    """``x,y,z,roll,pitch,yaw`` (m, rad) → array; SystemExit naming the rule otherwise, and,
    given the ``model``, for a position outside its workspace box (where no file of it
    promises the cables can hold the platform)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != 6 or not all(np.isfinite(values)):
        raise SystemExit(
            f"{what} = {text!r}: expected six finite numbers x,y,z,roll,pitch,yaw (m, rad)"
        )
    if model is not None:
        ws = model.workspace
        for k, axis in enumerate("xyz"):
            if not ws.position_min[k] <= values[k] <= ws.position_max[k]:
                raise SystemExit(
                    f"{what}: {axis} = {values[k]:g} m is outside the workspace box "
                    f"[{ws.position_min[k]:g}, {ws.position_max[k]:g}] m ([workspace] of "
                    f"{model.source_file})"
                )
    return np.array(values)
