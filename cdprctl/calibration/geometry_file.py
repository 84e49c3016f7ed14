"""The robot file of a geometric calibration: the original file as its ``base``, and every
cable again (``[[cables]]`` replaces the base's array whole) with its identified anchor and
its drum's identified radius (``[cables.winch] drum_radius``), everything else as it was; a
comment says when and how (docs/homing.md, "Geometric calibration")."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from cdprctl.model.robot import RobotModel
from cdprctl.robot_file.loader import read_merged


def _value(v: Any) -> str:
    """A TOML value: numbers, strings, booleans and arrays of them."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if isinstance(v, float) and not math.isfinite(v):
            raise ValueError(f"{v} is not a finite number")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)  # a TOML basic string for these texts
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise ValueError(f"{v!r} cannot be written as a TOML value here")


def calibrated_robot_text(model: RobotModel, anchors: np.ndarray, drum_radius: np.ndarray,
                          how: str) -> str:  # fmt: skip
    """The text of the calibrated robot file: ``anchors`` (m × 3 m, base frame) and
    ``drum_radius`` (m, per cable) identified, ``how`` a comment line (when, what)."""
    source = Path(model.source_file).resolve()
    data = read_merged(source)
    lines = [
        f"# {model.name} as built: anchors and drum radii identified by `cdprctl calibrate "
        "geometry`",
        f"# {how}",
        "# Everything else is the base file's; [[cables]] below replaces its cables whole.",
        f"base = {_value(str(source))}",
        "",
    ]
    for i, cable in enumerate(data["cables"]):
        lines.append("[[cables]]")
        tables: dict[str, dict[str, Any]] = {}
        for key, value in cable.items():
            if isinstance(value, dict):
                tables[key] = dict(value)
            elif key == "anchor":
                a = [round(float(x), 6) for x in anchors[i]]
                lines.append(f"anchor = {_value(a)}  # m, base frame (identified; drawn "
                             f"{_value([float(x) for x in value])})")  # fmt: skip
            else:
                lines.append(f"{key} = {_value(value)}")
        winch = tables.setdefault("winch", {})
        drawn = float(model.cables[i].winch.drum_radius)
        winch["drum_radius"] = float(f"{drum_radius[i]:.8g}")
        for name, table in tables.items():
            lines.append(f"[cables.{name}]")
            for key, value in table.items():
                note = (f"  # m (identified; the file's {drawn:g})"
                        if name == "winch" and key == "drum_radius" else "")  # fmt: skip
                lines.append(f"{key} = {_value(value)}{note}")
        lines.append("")
    if data.get("drives", {}).get("assume_home_at_start", False):
        # the record written with this file says where the platform stands: a start taken
        # as home would ignore it (rowc across processes: 31 mm off, the record right)
        lines += ["[drives]", "assume_home_at_start = false  # the start is the calibration "
                  "record's (the base file takes the encoders as zero at home)", ""]  # fmt: skip
    return "\n".join(lines)
