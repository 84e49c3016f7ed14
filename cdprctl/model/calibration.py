"""The ``[calibration]`` section: what the geometric calibration takes as drawn
(docs/homing.md, "Geometric calibration")."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprctl.model.reader import TableReader

CALIBRATION_KEYS = ("reference_anchors", "geometry_fill", "geometry_speed")

# the geometric calibration's plan: the fraction of the workspace box its poses span, the
# moves' mean speed (m/s); the file's value, else the procedure's default, else --fill/--speed
FILL_RANGE = (0.1, 1.0)
SPEED_RANGE = (0.01, 0.5)  # m/s


@dataclass(frozen=True)
class CalibrationConfig:
    # 0-based indices of the three anchors taken as drawn (they fix the robot's frame);
    # None: the three spanning the largest triangle (``reference_anchors``)
    reference_anchors: tuple[int, ...] | None = None
    # the geometric calibration's defaults for this robot (None: the procedure's own): a
    # large robot whose tensions change fast across its workspace plans closer to home
    geometry_fill: float | None = None
    geometry_speed: float | None = None  # m/s


def widest_triangle(anchors: np.ndarray) -> tuple[int, int, int]:
    """The three anchors (indices, m × 3 m) spanning the largest triangle, the first such in
    index order: spread references fix the frame best (rowc: 1.2·10³ against 8·10³ for three
    on one side; docs/homing.md)."""
    best, chosen = -1.0, (0, 1, 2)
    for i, j, k in itertools.combinations(range(len(anchors)), 3):
        area = float(np.linalg.norm(np.cross(anchors[j] - anchors[i], anchors[k] - anchors[i])))
        if area > best + 1e-9:
            best, chosen = area, (i, j, k)
    return chosen


def reference_anchors(config: CalibrationConfig, anchors: np.ndarray) -> tuple[int, int, int]:
    """The reference anchors' indices: the configured ones, else ``widest_triangle``."""
    if config.reference_anchors is not None:
        i, j, k = config.reference_anchors
        return i, j, k
    return widest_triangle(anchors)


def read_calibration(rd: TableReader, data: dict[str, Any], n_cables: int,
                     anchors: np.ndarray | None) -> CalibrationConfig:  # fmt: skip
    """``reference_anchors = [i, j, k]``: cable numbers as in the file (1-based: the first
    [[cables]] is 1), three distinct, their anchors not on one line; ``geometry_fill`` (a
    fraction in ``FILL_RANGE``) and ``geometry_speed`` (m/s in ``SPEED_RANGE``)."""
    t = rd.section(data, "calibration", CALIBRATION_KEYS)
    if t is None:
        return CalibrationConfig()
    fill = rd.number(t, "geometry_fill", "calibration", "", required=False,
                     minimum=FILL_RANGE[0], maximum=FILL_RANGE[1])  # fmt: skip
    speed = rd.number(t, "geometry_speed", "calibration", "m/s", required=False,
                      minimum=SPEED_RANGE[0], maximum=SPEED_RANGE[1])  # fmt: skip
    plan = CalibrationConfig(geometry_fill=fill, geometry_speed=speed)
    refs = t.get("reference_anchors")
    if refs is None:
        return plan
    path = "calibration.reference_anchors"
    if (not isinstance(refs, list) or len(refs) != 3
            or not all(isinstance(x, int) and not isinstance(x, bool) for x in refs)):  # fmt: skip
        rd.error(path, refs, "", "must be three cable numbers (1-based, as the [[cables]] "
                 "appear in the file)")  # fmt: skip
        return plan
    if len(set(refs)) != 3 or not all(1 <= x <= n_cables for x in refs):
        rd.error(path, refs, "", f"must be three distinct cable numbers in 1..{n_cables}")
        return plan
    idx = tuple(x - 1 for x in refs)
    if anchors is not None:
        a = anchors[list(idx)]
        if np.linalg.norm(np.cross(a[1] - a[0], a[2] - a[0])) < 1e-3:  # m²
            rd.error(path, refs, "", "must name anchors that are not on one line (they fix "
                     "the frame)")  # fmt: skip
            return plan
    return CalibrationConfig(reference_anchors=idx, geometry_fill=fill, geometry_speed=speed)
