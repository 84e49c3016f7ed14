"""The ``[paths]`` section: how path files are read (``cdprctl/motion/gcode.py``,
docs/operating.md "Formats")."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cdprctl.model.reader import TableReader

PATHS_KEYS = ("arc_tolerance",)
#: m: the bounds of ``arc_tolerance`` (0.01 mm: finer than a CAM file's rounding would refuse
#: its arcs; 10 mm: coarser is no longer the arc the file drew)
ARC_TOLERANCE_RANGE = (1e-5, 1e-2)


@dataclass(frozen=True)
class PathsConfig:
    # m: the largest distance between a G2/G3 arc and the chords it is played as (the chords'
    # sagitta), and the most its start and end radii may differ
    arc_tolerance: float = 1e-4


def read_paths(rd: TableReader, data: dict[str, Any]) -> PathsConfig:
    """``[paths]`` (optional; every key has a default). Errors go to ``rd``."""
    t = rd.section(data, "paths", PATHS_KEYS)
    if t is None:
        return PathsConfig()
    tol = rd.number(t, "arc_tolerance", "paths", "m", required=False,
                    default=PathsConfig.arc_tolerance)  # fmt: skip
    if tol is None:
        return PathsConfig()
    lo, hi = ARC_TOLERANCE_RANGE
    if not lo <= tol <= hi:
        rd.error("paths.arc_tolerance", tol, "m", f"must be in [{lo:g}, {hi:g}] m (0.01 mm to "
                 "10 mm: the largest distance between an arc and its chords)")  # fmt: skip
        return PathsConfig()
    return PathsConfig(arc_tolerance=tol)
