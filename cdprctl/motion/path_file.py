"""Path files: waypoints from a CSV table or a G-code subset (``docs/operating.md``).

CSV — a header naming the columns, then one waypoint per row; ``#`` starts a comment line:
    ``x, y, z`` (m, base frame; required), ``roll, pitch, yaw`` (rad; default: the start's),
    ``speed`` (m/s along the segment that ends at the row) or ``time`` (s from the path's
    start at which the row is reached; not both), ``blend`` (1: pass through the row without
    stopping), ``dwell`` (s held at the row). A row of units right after the header (``mm,
    mm, mm, deg, ...``; ``UNITS`` lists them) converts its columns; without one, ``units``
    (``--units``) says the lengths' (m, mm or in) and the speeds' (per s).

G-code — one block per line, words ``G0`` (at the configured speed), ``G1`` (at the feed
``F``), ``G4 P<s>`` (dwell), ``G20``/``G21`` (inches/mm: converted), ``G90``/``G91``
(absolute/relative), ``G61``/``G64`` (exact stop/blend through the following waypoints),
axes ``X Y Z`` (mm or in, base frame) and ``A B C`` (degrees, roll pitch yaw), ``F``
(mm/min or in/min), ``N`` (block numbers, ignored), ``M2``/``M30`` (end), comments in
``( )`` or after ``;``, ``%`` lines. Anything else is refused with its line and column.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from cdprctl.rotation import FloatArray


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


def parse_path(text: str, start: FloatArray, units: str = "m") -> list[Waypoint]:
    """The waypoints of a CSV or G-code path; ``start`` (x, y, z, roll, pitch, yaw; m, rad) is
    where it starts (the axes a file leaves out, G91's origin); ``units`` (m, mm or in): a
    CSV's lengths and speeds (per s) where it has no row of units (G-code says its own with
    G20/G21). Raises PathFileError."""
    if units not in LENGTH_UNITS:
        raise PathFileError(f"units = {units!r}: must be one of {', '.join(LENGTH_UNITS)}")
    start = np.asarray(start, dtype=float)
    lines = _content_lines(text)
    if not lines:
        raise PathFileError("the path file is empty")
    if _CSV_HEADER.match(lines[0]):
        return _csv(text, start, LENGTH_UNITS[units])
    return _gcode(text, start)


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


_WORD = re.compile(r"([A-Za-z])\s*([-+]?(\d+\.?\d*|\.\d+))")
_AXES = {"X": 0, "Y": 1, "Z": 2, "A": 3, "B": 4, "C": 5}
_G_CODES = {0, 1, 4, 20, 21, 61, 64, 90, 91}


def _strip_comments(line: str, no: int) -> str:
    """The line with ``( … )`` and ``; …`` blanked (columns kept for the messages)."""
    out = list(line)
    depth_start = -1
    for i, ch in enumerate(line):
        if depth_start < 0 and ch == ";":
            for j in range(i, len(line)):
                out[j] = " "
            break
        if ch == "(":
            if depth_start >= 0:
                raise PathFileError(f"line {no}, column {i + 1}: nested comment")
            depth_start = i
        if depth_start >= 0:
            out[i] = " "
        if ch == ")":
            if depth_start < 0:
                raise PathFileError(f"line {no}, column {i + 1}: ')' without '('")
            depth_start = -1
    if depth_start >= 0:
        raise PathFileError(f"line {no}, column {depth_start + 1}: comment not closed")
    return "".join(out)


def _gcode(text: str, start: FloatArray) -> list[Waypoint]:
    pos = np.array(start, dtype=float)
    unit = 1e-3  # m per file unit (G21: mm)
    relative = False
    blend = False
    feed: float | None = None  # m/s
    out: list[Waypoint] = []
    pending_dwell = 0.0  # a G4 before any motion: held at the start
    for no, raw in enumerate(text.splitlines(), 1):
        line = _strip_comments(raw, no)
        if not line.strip() or line.strip() == "%":
            continue
        words: list[tuple[str, float, int]] = []
        i = 0
        while i < len(line):
            if line[i].isspace():
                i += 1
                continue
            m = _WORD.match(line, i)
            if m is None:
                raise PathFileError(f"line {no}, column {i + 1}: {line[i:].split()[0]!r} is "
                                    f"not a G-code word (a letter and a number)")  # fmt: skip
            words.append((m.group(1).upper(), float(m.group(2)), i + 1))
            i = m.end()
        motion: int | None = None
        dwell: float | None = None
        axes: dict[int, float] = {}
        end = False
        for letter, value, col in words:
            if letter == "N":
                continue
            if letter == "G":
                code = int(value) if value == int(value) else -1
                if code not in _G_CODES:
                    raise PathFileError(
                        f"line {no}, column {col}: G{value:g} is not supported (supported: "
                        "G0 G1 G4 G20 G21 G61 G64 G90 G91)"
                    )
                if code in (0, 1):
                    if motion is not None or dwell is not None:
                        raise PathFileError(f"line {no}, column {col}: two motions in a block")
                    motion = code
                elif code == 4:
                    dwell = math.nan  # P follows
                elif code in (20, 21):
                    unit = 0.0254 if code == 20 else 1e-3
                elif code in (90, 91):
                    relative = code == 91
                else:
                    blend = code == 64
            elif letter in _AXES:
                if _AXES[letter] in axes:
                    raise PathFileError(f"line {no}, column {col}: {letter} given twice")
                axes[_AXES[letter]] = value
            elif letter == "F":
                if not value > 0:
                    raise PathFileError(f"line {no}, column {col}: F{value:g} must be > 0 "
                                        f"({'in' if unit > 1e-3 else 'mm'}/min)")  # fmt: skip
                feed = value * unit / 60.0
            elif letter == "P":
                if dwell is None:
                    raise PathFileError(f"line {no}, column {col}: P belongs to G4 (dwell)")
                if not 0.0 <= value <= 3600.0:
                    raise PathFileError(f"line {no}, column {col}: P{value:g} must be a dwell "
                                        f"in [0, 3600] s")  # fmt: skip
                dwell = value
            elif letter == "M":
                if value not in (2, 30):
                    raise PathFileError(f"line {no}, column {col}: M{value:g} is not supported "
                                        f"(only M2, M30: end of program)")  # fmt: skip
                end = True
            else:
                raise PathFileError(f"line {no}, column {col}: word {letter}{value:g} is not "
                                    f"supported")  # fmt: skip
        if dwell is not None:
            if math.isnan(dwell):
                raise PathFileError(f"line {no}: G4 needs P, the dwell in seconds")
            if axes:
                raise PathFileError(f"line {no}: G4 takes no axis words")
            if out:
                w = out[-1]
                out[-1] = Waypoint(w.pose, w.speed, w.time, False, w.dwell + dwell, w.where)
            else:
                pending_dwell += dwell
        if axes and motion is None:
            raise PathFileError(f"line {no}: axis words need G0 or G1 in the same block "
                                f"(modal motion is not supported)")  # fmt: skip
        if motion is not None:
            if not axes:
                raise PathFileError(f"line {no}: G{motion} without an axis word")
            if motion == 1 and feed is None:
                raise PathFileError(f"line {no}: G1 needs a feed rate F (mm/min or in/min) "
                                    f"first")  # fmt: skip
            for k, v in axes.items():
                scale = unit if k < 3 else math.pi / 180.0
                pos[k] = pos[k] + v * scale if relative else v * scale
            if pending_dwell and not out:
                s = tuple(float(x) for x in start)
                out.append(Waypoint(s, None, None, False, pending_dwell, f"line {no}"))  # type: ignore[arg-type]
            out.append(Waypoint(tuple(float(x) for x in pos), feed if motion == 1 else None,  # type: ignore[arg-type]
                                None, blend, 0.0, f"line {no}"))  # fmt: skip
        if end:
            break
    if not out:
        raise PathFileError("the G-code has no motion (G0/G1 with axis words)")
    return out
