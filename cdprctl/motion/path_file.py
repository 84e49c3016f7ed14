"""Path files: waypoints from a CSV table or a G-code subset (``docs/operating.md``).

CSV — a header naming the columns, then one waypoint per row; ``#`` starts a comment line:
    ``x, y, z`` (m, base frame; required), ``roll, pitch, yaw`` (rad; default: the start's),
    ``speed`` (m/s along the segment that ends at the row) or ``time`` (s from the path's
    start at which the row is reached; not both), ``blend`` (1: pass through the row without
    stopping), ``dwell`` (s held at the row). A row of units right after the header (``mm,
    mm, mm, deg, ...``; ``UNITS`` lists them) converts its columns; without one, ``units``
    (``--units``) says the lengths' (m, mm or in) and the speeds' (per s).

G-code — read by ``gcode.py`` (modal motion, feed, units, distances, planes, G2/G3 arcs as
chords; every other word taken, ignored or refused there, one by one).
"""

from __future__ import annotations

import math
import re

import numpy as np

from cdprctl.core.rotation import FloatArray
from cdprctl.motion.gcode import read_gcode
from cdprctl.motion.waypoints import PathFileError, Waypoint


def parse_path(
    text: str, start: FloatArray, units: str = "m", arc_tolerance: float = 1e-4
) -> list[Waypoint]:
    """The waypoints of a CSV or G-code path; ``start`` (x, y, z, roll, pitch, yaw; m, rad) is
    where it starts (the axes a file leaves out, G91's origin); ``units`` (m, mm or in): a
    CSV's lengths and speeds (per s) where it has no row of units (G-code says its own with
    G20/G21); ``arc_tolerance`` (m): G2/G3's chords' largest distance to the arc (``[paths]
    arc_tolerance``). Raises PathFileError."""
    if units not in LENGTH_UNITS:
        raise PathFileError(f"units = {units!r}: must be one of {', '.join(LENGTH_UNITS)}")
    start = np.asarray(start, dtype=float)
    lines = _content_lines(text)
    if not lines:
        raise PathFileError("the path file is empty")
    if _CSV_HEADER.match(lines[0]):
        return _csv(text, start, LENGTH_UNITS[units])
    return read_gcode(text, start, arc_tolerance)


_CSV_HEADER = re.compile(r"^[a-zA-Z_]+\s*,")  # a CSV's first line; G-code words carry numbers


def _content_lines(text: str) -> list[str]:
    """The lines that are neither blank nor ``#`` comments, stripped."""
    return [s for s in (ln.strip() for ln in text.splitlines()) if s and not s.startswith("#")]


def csv_without_units(text: str) -> bool:
    """Whether ``text`` is a CSV path with no row of units under its header (its lengths are
    then the ``units`` given, m by default)."""
    lines = _content_lines(text)
    if not lines or not _CSV_HEADER.match(lines[0]):
        return False
    return len(lines) < 2 or not all(_UNIT_WORD.fullmatch(c.strip()) for c in lines[1].split(","))



CSV_COLUMNS = ("x", "y", "z", "roll", "pitch", "yaw", "speed", "time", "blend", "dwell")
_CSV_UNITS = {"x": "m", "y": "m", "z": "m", "roll": "rad", "pitch": "rad", "yaw": "rad",
              "speed": "m/s", "time": "s", "blend": "0 or 1", "dwell": "s"}  # fmt: skip
LENGTH_UNITS = {"m": 1.0, "mm": 1e-3, "in": 0.0254}  # m per unit
#: a unit row's words, per column, and the SI value of one of each (m, rad, m/s, s)
UNITS = {
    "x": LENGTH_UNITS, "y": LENGTH_UNITS, "z": LENGTH_UNITS,
    "roll": {"rad": 1.0, "deg": math.pi / 180.0}, "pitch": {"rad": 1.0, "deg": math.pi / 180.0},
    "yaw": {"rad": 1.0, "deg": math.pi / 180.0},
    "speed": {"m/s": 1.0, "mm/s": 1e-3, "mm/min": 1e-3 / 60.0, "in/s": 0.0254,
              "in/min": 0.0254 / 60.0},
    "time": {"s": 1.0, "ms": 1e-3}, "dwell": {"s": 1.0, "ms": 1e-3}, "blend": {"-": 1.0},
}  # fmt: skip


_UNIT_WORD = re.compile(r"(?!(?i:nan|inf|infinity)$)[a-zA-Z/-]*")  # not a number's word


def _unit_row(cells: list[str], header: list[str], no: int) -> list[float]:
    """The SI value of one unit of each column, from a row of unit words."""
    out = []
    for col, (name, word) in enumerate(zip(header, cells, strict=True)):
        known = UNITS[name]
        unit = word.lower() or ("-" if name == "blend" else "")
        if unit not in known:
            raise PathFileError(f"line {no}, column {col + 1}: {word!r} is not a unit of {name} "
                                f"(one of: {', '.join(known)})")  # fmt: skip
        out.append(known[unit])
    return out


def _csv(text: str, start: FloatArray, length_unit: float) -> list[Waypoint]:
    header: list[str] | None = None
    scale: list[float] = []  # SI per file unit, per column
    out: list[Waypoint] = []
    last_time = 0.0
    for no, raw in enumerate(text.splitlines(), 1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        cells = [c.strip() for c in line.split(",")]
        if header is None:
            header = [c.lower() for c in cells]
            for col, name in enumerate(header):
                if name not in CSV_COLUMNS:
                    raise PathFileError(
                        f"line {no}, column {col + 1}: {name!r} is not a column "
                        f"(known: {', '.join(CSV_COLUMNS)})"
                    )
                if header.count(name) > 1:
                    raise PathFileError(f"line {no}: column {name!r} appears twice")
            missing = [c for c in ("x", "y", "z") if c not in header]
            if missing:
                raise PathFileError(f"line {no}: the header needs x, y, z (missing: "
                                    f"{', '.join(missing)})")  # fmt: skip
            if "speed" in header and "time" in header:
                raise PathFileError(f"line {no}: give speed or time, not both")
            lengths = ("x", "y", "z", "speed")  # speeds per s: mm/s with mm
            scale = [length_unit if name in lengths else 1.0 for name in header]
            continue
        if len(cells) != len(header):
            raise PathFileError(
                f"line {no}: {len(cells)} values for {len(header)} columns ({', '.join(header)})"
            )
        if not out and all(_UNIT_WORD.fullmatch(c) for c in cells):  # a row of units
            scale = _unit_row(cells, header, no)
            continue
        row: dict[str, float] = {}
        for col, (name, cell) in enumerate(zip(header, cells, strict=True)):
            try:
                v = float(cell)
            except ValueError:
                v = math.nan
            if not math.isfinite(v):
                raise PathFileError(f"line {no}, column {col + 1}: {name} = {cell!r} must be a "
                                    f"finite number ({_CSV_UNITS[name]})")  # fmt: skip
            row[name] = v * scale[col]
        where = f"line {no}"
        speed = row.get("speed")
        if speed is not None and not speed > 0:
            raise PathFileError(f"{where}: speed = {speed:g} m/s must be > 0")
        t = row.get("time")
        if t is not None:
            if not t > last_time:
                raise PathFileError(
                    f"{where}: time = {t:g} s must be later than the previous waypoint's "
                    f"{last_time:g} s (times count from the path's start)"
                )
            last_time = t
        blend = row.get("blend", 0.0)
        if blend not in (0.0, 1.0):
            raise PathFileError(f"{where}: blend = {blend:g} must be 0 or 1")
        dwell = row.get("dwell", 0.0)
        if not 0.0 <= dwell <= 3600.0:
            raise PathFileError(f"{where}: dwell = {dwell:g} s must be in [0, 3600] s")
        pose = tuple(row.get(name, float(start[k]))
                     for k, name in enumerate(CSV_COLUMNS[:6]))  # fmt: skip
        out.append(Waypoint(pose, speed, t, blend == 1.0, dwell, where))  # type: ignore[arg-type]
    if not out:
        raise PathFileError("the path file has a header but no waypoint")
    return out
