"""Load and validate a robot description (TOML) into a frozen :class:`RobotModel`.

The whole file is checked and every problem reported at once (:class:`ConfigError`); a model is
returned only when the file is entirely valid. See ``docs/config.md`` for the keys.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.model.cables import read_cables, read_winch
from cdprctl.model.calibration import read_calibration
from cdprctl.model.control import read_control
from cdprctl.model.drives import read_drives
from cdprctl.model.errors import ConfigError
from cdprctl.model.foxglove import read_foxglove
from cdprctl.model.grippers import read_grippers
from cdprctl.model.interference import read_interference
from cdprctl.model.paths import read_paths
from cdprctl.model.reader import TableReader
from cdprctl.model.robot import Platform, Pose, RobotModel, Workspace
from cdprctl.model.ros2 import read_ros2
from cdprctl.model.safety import read_safety
from cdprctl.model.sensors import read_sensors
from cdprctl.model.zenoh import read_zenoh

TOP_KEYS = (
    "name",
    "source",
    "gravity",
    "platform",
    "home",
    "workspace",
    "winch",
    "cables",
    "drives",
    "control",
    "zenoh",
    "foxglove",
    "ros2",
    "grippers",
    "calibration",
    "safety",
    "paths",
    "cell",
    "interference",
    "sensors",
)
PLATFORM_KEYS = ("mass", "com", "inertia", "body")  # body: model/interference.py
HOME_KEYS = ("position", "rpy")
WORKSPACE_KEYS = ("position_min", "position_max", "max_angle", "wrench_margin")

def load_robot(path: str | Path) -> RobotModel:
    """Read, validate and freeze the robot description in ``path``.

    A file may start from another: ``base = "other.toml"`` (relative to the file) takes every
    key of that file; its own tables are merged into the base's key by key, its values and
    arrays (``[[cables]]`` included) replace the base's.

    Raises
    ------
    ConfigError
        With every problem of the file, each naming the key, the value, the unit and the rule.
    """
    path = Path(path)
    return parse_robot(_read_toml(path, []), str(path))


def read_merged(path: str | Path) -> dict[str, Any]:
    """The robot file's TOML with its ``base`` files merged in (what ``load_robot`` checks):
    for tools that write a robot file derived from it."""
    return _read_toml(Path(path), [])


def _read_toml(path: Path, chain: list[Path]) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError([f"{path}: cannot read the file: {exc.strerror or exc}"]) from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError([f"{path}: not valid TOML: {exc}"]) from exc
    base = data.pop("base", None)
    if base is None:
        return data
    if not isinstance(base, str) or not base.strip():
        raise ConfigError([f"{path}: base = {base!r} must be the path of a robot TOML file"])
    base_path = (path.parent / base).resolve()
    if base_path in chain or base_path == path.resolve():
        raise ConfigError([f"{path}: base = {base!r} includes itself (a cycle of base files)"])
    if len(chain) >= 8:
        raise ConfigError([f"{path}: base = {base!r}: more than 8 base files deep"])
    return _merge(_read_toml(base_path, [*chain, path.resolve()]), data)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


# the sections without which there is no robot (a None: its reader said why)
_REQUIRED = ("name", "gravity", "platform", "cables", "home", "workspace", "drives", "control",
             "zenoh", "foxglove", "ros2", "grippers")  # fmt: skip


def parse_robot(data: dict[str, Any], file: str) -> RobotModel:
    """Validate an already-parsed TOML document (see :func:`load_robot`)."""
    rd = TableReader(file)
    rd.check_keys(data, TOP_KEYS, "")
    parts = _read_sections(rd, data)
    if rd.errors or any(parts[k] is None for k in _REQUIRED):
        raise ConfigError(rd.errors or [f"{file}: invalid"])
    # the grippers' drives stay in torque mode: their cables' tensions squeeze the jaws,
    # which position mode would hold as lengths instead (64 mm of tracking error in
    # seed000_grippers' demo, all eight drives in position mode; lock-step)
    parts["drives"] = dataclasses.replace(
        parts["drives"], torque_cables=tuple(sorted(g.cable for g in parts["grippers"]))
    )
    parts["cables"] = tuple(parts["cables"])
    model = RobotModel(source_file=file, **parts)
    # Checks that need the assembled geometry.
    from cdprctl.robot_file.checks import check_model  # late import: checks use the kinematics

    errors = check_model(model)
    if errors:
        raise ConfigError(errors)
    return model


def _read_sections(rd: TableReader, data: dict[str, Any]) -> dict[str, Any]:
    """Every section of the document by its ``RobotModel`` field, each read by its own reader
    (None where it is missing or wrong: the reader has said why in ``rd.errors``, in the
    document's order); the sections that name the cables after them."""
    name = rd.string(data, "name", "")
    out: dict[str, Any] = {
        "name": name,
        "source": rd.string(data, "source", "", required=False, default="") or "",
        "gravity": rd.vector(data, "gravity", "", "m/s²"),
        "platform": _read_platform(rd, data),
    }
    winch_table = rd.table(data, "winch", "", required=False)
    default_winch = read_winch(rd, winch_table, "winch", None) if winch_table else None
    cables = read_cables(rd, data, winch_table is not None, default_winch)
    names = [c.name for c in cables or ()]
    out |= {"cables": cables, "home": _read_home(rd, data),
            "workspace": _read_workspace(rd, data), "drives": None}  # fmt: skip
    if cables is not None:
        rated = max(c.winch.torque_limit for c in cables)
        out["drives"] = read_drives(rd, data, names, name or "robot", rated, rated)
    drives = out["drives"]
    anchors = np.array([c.anchor for c in cables], float) if cables else None
    out["control"] = read_control(rd, data, names)
    out["zenoh"] = read_zenoh(rd, data, name or "robot")
    out["foxglove"] = read_foxglove(rd, data)
    out["ros2"] = read_ros2(rd, data)
    out["grippers"] = read_grippers(rd, data, cables)
    out["calibration"] = read_calibration(rd, data, len(cables or ()), anchors)
    out["safety"] = read_safety(rd, data)
    out["paths"] = read_paths(rd, data)
    out["interference"] = read_interference(rd, data)
    out["sensors"] = read_sensors(rd, data, names, drives.buses if drives else (),
                                  drives.controller_node_id if drives else 127,
                                  drives.driver if drives else "cia402")  # fmt: skip
    return out


def _read_platform(rd: TableReader, data: dict[str, Any]) -> Platform | None:
    t = rd.table(data, "platform", "")
    if t is None:
        return None
    rd.check_keys(t, PLATFORM_KEYS, "platform")
    mass = rd.number(t, "mass", "platform", "kg", positive=True)
    com = rd.vector(t, "com", "platform", "m", required=False, default=np.zeros(3))
    inertia = rd.matrix3(t, "inertia", "platform", "kg·m²")
    if inertia is not None:
        if not np.allclose(
            inertia, inertia.T, rtol=0.0, atol=1e-9 * max(1.0, np.abs(inertia).max())
        ):
            rd.error("platform.inertia", inertia, "kg·m²", "must be symmetric")
            inertia = None
        else:
            eig = np.linalg.eigvalsh(inertia)
            if eig.min() <= 0.0:
                rd.error("platform.inertia", inertia, "kg·m²", "must be positive definite")
                inertia = None
            elif eig[0] + eig[1] < eig[2] * (1.0 - 1e-9):
                rd.error(
                    "platform.inertia",
                    inertia,
                    "kg·m²",
                    "breaks the triangle inequality of principal moments (I1 + I2 >= I3): "
                    "no rigid body has it",
                )
                inertia = None
    if mass is None or com is None or inertia is None:
        return None
    return Platform(mass=mass, com=com, inertia=inertia)


def _read_home(rd: TableReader, data: dict[str, Any]) -> Pose | None:
    t = rd.section(data, "home", HOME_KEYS, required=True)
    if t is None:
        return None
    position = rd.vector(t, "position", "home", "m")
    rpy = rd.rpy(t, "rpy", "home")
    if position is None or rpy is None:
        return None
    return Pose(position=position, rpy=rpy)


def _read_workspace(rd: TableReader, data: dict[str, Any]) -> Workspace | None:
    t = rd.section(data, "workspace", WORKSPACE_KEYS, required=True)
    if t is None:
        return None
    lo = rd.vector(t, "position_min", "workspace", "m")
    hi = rd.vector(t, "position_max", "workspace", "m")
    max_angle = rd.number(t, "max_angle", "workspace", "rad", positive=True, maximum=math.pi)
    margin = rd.number(t, "wrench_margin", "workspace", "N", required=False, default=None,
                       minimum=0.0)  # fmt: skip
    if lo is not None and hi is not None:
        for k, axis in enumerate("xyz"):
            if lo[k] >= hi[k]:
                rd.error(
                    f"workspace.position_min[{k}]",
                    float(lo[k]),
                    "m",
                    f"must be < position_max[{k}] = {hi[k]:g} m ({axis})",
                )
                lo = None
                break
    if lo is None or hi is None or max_angle is None:
        return None
    return Workspace(position_min=lo, position_max=hi, max_angle=max_angle, wrench_margin=margin)
