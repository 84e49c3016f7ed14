"""G-code path files as CAM programs and slicers write them (docs/operating.md, "G-code").

LinuxCNC's meanings. Modal as there: the motion (G0 G1 G2 G3, until G80), the feed F, the
units (G21 mm, the default; G20 in), the distances (G90 absolute, the default; G91 relative),
the arc centres (G91.1 from the start, the default; G90.1 absolute), the plane (G17 XY, the
default; G18 ZX; G19 YZ) and blending (G61 exact stop, the default; G64 blend). Within a
block the modes apply before its motion, whatever the words' order. Arcs are played as
chords within ``[paths] arc_tolerance`` (``arcs.py``).

Every other word is decided here, one by one: taken and ignored where it cannot move the
robot (``IGNORED_G``, ``IGNORED_M``, ``IGNORED_LETTERS``), refused with why where it would
change the path's meaning (``REFUSED_G``, ``REFUSED_M``, ``REFUSED_LETTERS``), refused as
unsupported otherwise.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from cdprctl.core.rotation import FloatArray
from cdprctl.motion import arcs
from cdprctl.motion.waypoints import PathFileError, Waypoint

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(\d+\.?\d*|\.\d+))")
AXES = {"X": 0, "Y": 1, "Z": 2, "A": 3, "B": 4, "C": 5}
#: G codes taken (×10: G91.1 is 911) → their modal group (two of one group: one block refused)
GROUPS = {0: "motion", 10: "motion", 20: "motion", 30: "motion", 40: "motion", 800: "motion",
          170: "plane", 180: "plane", 190: "plane", 200: "units", 210: "units",
          900: "distance", 910: "distance", 901: "arc centres", 911: "arc centres",
          610: "path control", 640: "path control", 400: "cutter compensation",
          490: "tool length offset", 540: "coordinate system", 940: "feed rate mode"}  # fmt: skip
#: taken, and nothing to do: each says what is already so
IGNORED_G = {400: "cutter compensation off", 490: "tool length offset off",
             540: "the base frame (the only coordinates)", 940: "feed in units per minute"}
#: refused: each would change what the path means
REFUSED_G = {
    100: "it sets offsets; the path's coordinates are the base frame's",
    280: "it goes to a stored home position; the robot's home is not a G-code one",
    300: "it goes to a stored home position; the robot's home is not a G-code one",
    410: "cutter compensation would offset the path by a radius the robot does not know",
    420: "cutter compensation would offset the path by a radius the robot does not know",
    430: "a tool length offset would shift z by a length the robot does not know",
    530: "machine coordinates for one block; the path's coordinates are the base frame's",
    **{550 + 10 * k: "another work offset; only G54, the base frame, exists here"
       for k in range(5)},
    **{810 + 10 * k: "a canned cycle" for k in range(9)},
    920: "it shifts the coordinates; the path's coordinates are the base frame's",
    930: "inverse-time feed: F would be 1/min, not mm/min",
    950: "feed per revolution: there is no spindle",
}  # fmt: skip
END_M = (2, 30)
#: taken, and ignored: the robot has none of these
IGNORED_M = {1: "optional stop, as with its switch off", 3: "spindle", 4: "spindle",
             5: "spindle", 6: "tool change", 7: "coolant", 8: "coolant", 9: "coolant"}
REFUSED_M = {0: "a pause for the operator; the path does not wait: use G4 P<s> or the pause "
                "command"}  # fmt: skip
IGNORED_LETTERS = {"N": "block number", "T": "tool number", "S": "spindle speed"}
REFUSED_LETTERS = {"E": "an extruder's axis; the robot has no extruder"}
#: letters read: the axes, the arc's centre (I J K) or radius (R), feed, dwell or turns (P)
READ_LETTERS = set(AXES) | set("IJKRFP")
MAX_CHORDS = 10000  # per arc: more is a file or a tolerance that cannot be meant


@dataclass
class Modes:
    """The modal state between blocks (SI: m per file unit, m/s)."""

    pos: FloatArray  # x, y, z (m), roll, pitch, yaw (rad): where the last block ended
    unit: float = 1e-3  # m per file unit (G21)
    relative: bool = False  # G91
    arc_absolute: bool = False  # G90.1
    blend: bool = False  # G64
    feed: float | None = None  # m/s
    motion: int | None = None  # 0 1 2 3; None: at the start and after G80
    plane: int = 17
    out: list[Waypoint] = field(default_factory=list)
    pending_dwell: float = 0.0  # s: a G4 before any motion, held at the start


@dataclass
class Block:
    no: int  # the file's line
    g: dict[str, tuple[int, int]]  # modal group → (code ×10, column)
    words: dict[str, tuple[float, int]]  # letter → (value, column); not G, M or ignored ones
    end: bool  # M2 or M30


def strip_comments(line: str, no: int) -> str:
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


def _words(line: str, no: int) -> list[tuple[str, float, int]]:
    """(letter, value, column) of each word of a comment-free line."""
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
    return words


def _g_code(value: float, no: int, col: int) -> int:
    """A G word's code ×10, taken or refused with why."""
    code = round(value * 10)
    where = f"line {no}, column {col}: G{value:g}"
    if abs(code - value * 10) > 1e-6 or not (code in GROUPS or code in REFUSED_G):
        raise PathFileError(f"{where} is not supported (supported: G0 G1 G2 G3 G4 G17 G18 G19 "
                            "G20 G21 G40 G49 G54 G61 G64 G80 G90 G90.1 G91 G91.1 G94)")
    if code in REFUSED_G:
        raise PathFileError(f"{where} is refused: {REFUSED_G[code]}")
    return code


def _m_code(value: float, no: int, col: int) -> bool:
    """Whether an M word ends the program; refused unless taken or ignored."""
    code = int(value) if value == int(value) else -1
    if code in REFUSED_M:
        raise PathFileError(f"line {no}, column {col}: M{value:g} is refused: {REFUSED_M[code]}")
    if code not in END_M and code not in IGNORED_M:
        raise PathFileError(f"line {no}, column {col}: M{value:g} is not supported (taken: "
                            "M2 M30 end; M1 M3 M4 M5 M6 M7 M8 M9 ignored)")  # fmt: skip
    return code in END_M


def read_block(line: str, no: int) -> Block:
    """A line's words sorted into a block; a word twice, two of one modal group, an unknown
    or refused word: PathFileError naming its line and column."""
    block = Block(no, {}, {}, False)
    for letter, value, col in _words(line, no):
        if letter == "G":
            code = _g_code(value, no, col)
            group = GROUPS.get(code, "")
            if group in block.g:
                if group == "motion":
                    raise PathFileError(f"line {no}, column {col}: two motions in a block")
                raise PathFileError(f"line {no}, column {col}: G{value:g} and G"
                                    f"{block.g[group][0] / 10:g} in one block: both set the "
                                    f"{group}")  # fmt: skip
            block.g[group] = (code, col)
        elif letter == "M":
            block.end = _m_code(value, no, col) or block.end
        elif letter in IGNORED_LETTERS:
            continue
        elif letter in READ_LETTERS:
            if letter in block.words:
                raise PathFileError(f"line {no}, column {col}: {letter} given twice")
            block.words[letter] = (value, col)
        else:
            why = f" ({REFUSED_LETTERS[letter]})" if letter in REFUSED_LETTERS else ""
            raise PathFileError(f"line {no}, column {col}: word {letter}{value:g} is not "
                                f"supported{why}")  # fmt: skip
    return block


def _set_modes(b: Block, m: Modes) -> None:
    """The block's modal words, before its motion (units before the feed it scales)."""
    code = {group: c for group, (c, _) in b.g.items()}
    if "units" in code:
        m.unit = 0.0254 if code["units"] == 200 else 1e-3
    if "F" in b.words:
        f, col = b.words["F"]
        if not f > 0:
            raise PathFileError(f"line {b.no}, column {col}: F{f:g} must be > 0 "
                                f"({'in' if m.unit > 1e-3 else 'mm'}/min)")  # fmt: skip
        m.feed = f * m.unit / 60.0
    m.plane = code.get("plane", m.plane * 10) // 10
    m.relative = code.get("distance", 910 if m.relative else 900) == 910
    m.arc_absolute = code.get("arc centres", 901 if m.arc_absolute else 911) == 901
    m.blend = code.get("path control", 640 if m.blend else 610) == 640
    motion = code.get("motion")
    if motion is not None and motion != 40:
        m.motion = None if motion == 800 else motion // 10


def _dwell(b: Block, m: Modes) -> None:
    """G4: P seconds held at the last waypoint (at the start before any motion)."""
    if "P" not in b.words:
        raise PathFileError(f"line {b.no}: G4 needs P, the dwell in seconds")
    p, col = b.words["P"]
    if not 0.0 <= p <= 3600.0:
        raise PathFileError(f"line {b.no}, column {col}: P{p:g} must be a dwell in [0, 3600] s")
    given = [k for k in b.words if k in AXES or k in "IJKR"]
    if given:
        raise PathFileError(f"line {b.no}: G4 takes no axis words ({', '.join(given)} given)")
    if m.out:
        w = m.out[-1]
        m.out[-1] = Waypoint(w.pose, w.speed, w.time, False, w.dwell + p, w.where)
    else:
        m.pending_dwell += p


def _target(b: Block, m: Modes) -> FloatArray:
    """The pose the block's axis words go to (absolute or relative, in the file's units)."""
    pos = m.pos.copy()
    for letter, k in AXES.items():
        if letter in b.words:
            v = b.words[letter][0] * (m.unit if k < 3 else math.pi / 180.0)
            pos[k] = pos[k] + v if m.relative else v
    return pos


def _check_words(b: Block, m: Modes, moves: bool) -> None:
    """The words that belong to a motion: with one, and P with G4 or an arc only."""
    arc = m.motion in (2, 3)
    for letter, (value, col) in b.words.items():
        if letter == "P" and "motion" in b.g and b.g["motion"][0] == 40:
            continue
        if letter == "P" and not arc:
            raise PathFileError(f"line {b.no}, column {col}: P belongs to G4 (dwell) or G2/G3 "
                                "(turns)")  # fmt: skip
        if letter in "IJKR" and not arc:
            raise PathFileError(f"line {b.no}, column {col}: {letter}{value:g} belongs to G2/G3 "
                                "(the arc's centre or radius)")  # fmt: skip
    if moves and m.motion is None:
        raise PathFileError(f"line {b.no}: axis words need a motion mode: G0, G1, G2 or G3 on "
                            "this line or one before (none since the start or G80)")  # fmt: skip
    if moves and m.motion != 0 and m.feed is None:
        raise PathFileError(f"line {b.no}: G{m.motion} needs a feed rate F (mm/min or in/min) "
                            f"first")  # fmt: skip


def _add(m: Modes, pose: FloatArray, no: int) -> None:
    """A waypoint at ``pose`` at the mode's speed and blending."""
    if m.pending_dwell and not m.out:
        s = tuple(float(x) for x in m.pos)
        m.out.append(Waypoint(s, None, None, False, m.pending_dwell, f"line {no}"))  # type: ignore[arg-type]
    speed = None if m.motion == 0 else m.feed
    m.out.append(Waypoint(tuple(float(x) for x in pose), speed, None, m.blend, 0.0,  # type: ignore[arg-type]
                          f"line {no}"))  # fmt: skip
    m.pos = np.array(pose, dtype=float)


def _arc(b: Block, m: Modes, end: FloatArray, tolerance: float) -> list[FloatArray]:
    """The chords' ends of the block's G2/G3 from where the last block ended to ``end``
    (a pose), within ``tolerance`` (m)."""
    first, second, other = arcs.OFFSET_WORDS[m.plane]
    name, plane = f"G{m.motion}", f"G{m.plane}"
    if b.words.get(other, (0.0, 0))[0] != 0.0:  # an offset off the plane: 0 says nothing
        raise PathFileError(f"line {b.no}, column {b.words[other][1]}: {other} is no centre "
                            f"offset in the {plane} plane (its offsets: {first} {second})")
    i, j = arcs.PLANES[m.plane]
    s, e = m.pos[[i, j]], end[[i, j]]
    cw = m.motion == 2
    given = [w for w in (first, second) if w in b.words]
    if "R" in b.words:
        r, col = b.words["R"]
        if given:
            raise PathFileError(f"line {b.no}, column {col}: {name}: give the centre "
                                f"({first} {second}) or the radius R, not both")  # fmt: skip
        try:
            centre = arcs.centre_from_radius(s, e, r * m.unit, cw, tolerance)
        except arcs.ArcError as exc:
            raise PathFileError(f"line {b.no}, column {col}: {name} R{r:g}: {exc}") from None
    elif m.arc_absolute and len(given) == 2:
        centre = np.array([b.words[first][0], b.words[second][0]]) * m.unit
    elif given and not m.arc_absolute:
        centre = s + np.array([b.words.get(w, (0.0, 0))[0] for w in (first, second)]) * m.unit
    else:
        mode = "both, absolute (G90.1)" if m.arc_absolute else "from the start (G91.1)"
        raise PathFileError(f"line {b.no}: {name} needs its centre, {first} {second} {mode}, "
                            f"or its radius R")  # fmt: skip
    turns = _turns(b)
    r0, r1 = float(np.hypot(*(s - centre))), float(np.hypot(*(e - centre)))
    if r0 <= arcs.SAME_POINT:
        raise PathFileError(f"line {b.no}: {name}: the centre is the start (radius 0)")
    if abs(r1 - r0) > tolerance:
        raise PathFileError(
            f"line {b.no}: {name}: the radius at the start, {r0 * 1e3:.4f} mm, and at the end, "
            f"{r1 * 1e3:.4f} mm, differ by {abs(r1 - r0) * 1e3:.4f} mm, more than [paths] "
            f"arc_tolerance = {tolerance * 1e3:g} mm (is the centre or the end wrong?)")
    n = arcs.chords(max(r0, r1), arcs.sweep(s, e, centre, cw, turns), tolerance)
    if n > MAX_CHORDS:
        raise PathFileError(f"line {b.no}: {name} needs {n} chords within [paths] "
                            f"arc_tolerance = {tolerance * 1e3:g} mm: more than {MAX_CHORDS}")
    return arcs.arc_points(m.pos, end, centre, m.plane, cw, turns, tolerance)


def _turns(b: Block) -> int:
    """An arc's P: how many times it goes round (1 without P)."""
    if "P" not in b.words:
        return 1
    p, col = b.words["P"]
    if p != int(p) or p < 1:
        raise PathFileError(f"line {b.no}, column {col}: P{p:g} must be a whole number of "
                            "turns, 1 or more")  # fmt: skip
    return int(p)


def read_gcode(text: str, start: FloatArray, arc_tolerance: float) -> list[Waypoint]:
    """The waypoints of a G-code file from ``start`` (x, y, z m, roll, pitch, yaw rad); its
    arcs as chords within ``arc_tolerance`` (m). Raises PathFileError."""
    m = Modes(pos=np.array(start, dtype=float))
    percents = 0
    for no, raw in enumerate(text.splitlines(), 1):
        line = strip_comments(raw, no).strip()
        if line == "%":
            percents += 1
            if percents == 2:  # the second % ends the program, as M2
                break
            continue
        if not line:
            continue
        b = read_block(line, no)
        _set_modes(b, m)
        if b.g.get("motion", (0, 0))[0] == 40:
            _dwell(b, m)
        else:
            moves = any(k in AXES or k in "IJKR" for k in b.words)
            _check_words(b, m, moves)
            if moves and m.motion in (2, 3):
                for pose in _arc(b, m, _target(b, m), arc_tolerance):
                    _add(m, pose, no)
            elif moves:
                _add(m, _target(b, m), no)
        if b.end:
            break
    if not m.out:
        raise PathFileError("the G-code has no motion (G0 G1 G2 G3 with axis words)")
    return m.out


#: file units: a G-code file without G20/G21 whose X Y Z are all smaller than this reads, as
#: the default mm, within 5 mm of the origin: metres, most likely
METRE_LIKE = 5.0


def looks_like_metres(text: str) -> bool:
    """Whether ``text`` is G-code that says no units (G20/G21) and whose X Y Z words are all
    smaller than ``METRE_LIKE``: numbers in metres, read as mm."""
    lengths, units = [], False
    for no, raw in enumerate(text.splitlines(), 1):
        try:
            words = _words(strip_comments(raw, no).strip().strip("%"), no)
        except PathFileError:
            return False  # not G-code, or its error says more
        lengths += [v for letter, v, _ in words if letter in "XYZ"]
        units = units or any(letter == "G" and v in (20.0, 21.0) for letter, v, _ in words)
    return bool(lengths) and not units and max(abs(v) for v in lengths) < METRE_LIKE
