"""What a path file reads into, whatever its format (CSV: ``path_file.py``, G-code:
``gcode.py``): the waypoints, and the error that names where a file is wrong."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Waypoint:
    pose: tuple[float, float, float, float, float, float]  # x, y, z (m), roll, pitch, yaw (rad)
    speed: float | None  # m/s along the segment ending here; None: the configured maximum
    time: float | None  # s after the path's start at which it is reached
    blend: bool  # pass through without stopping
    dwell: float  # s held here
    where: str  # "line 7" (the file's line, 1-based)


class PathFileError(ValueError):
    """A path file that cannot be read: the message names the line, the column, the value,
    the unit and the rule."""
