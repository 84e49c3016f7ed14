"""The interference sections of a robot description (issue 67; ``cdprctl/geometry/interference.py``
measures them): the platform's body (``[[platform.body.boxes]]``, platform frame), the cell's
obstacles (``[[cell.obstacles]]``, base frame: boxes and planes) and ``[interference]``
(``clearance``, ``attachment_exclusion``). Every key is optional: a robot without them has no
body, no obstacle, and its cables are checked against each other only."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from cdprctl.core.rotation import FloatArray, rpy_to_matrix
from cdprctl.model.reader import TableReader

INTERFERENCE_KEYS = ("clearance", "attachment_exclusion")
BODY_KEYS = ("boxes",)
BOX_KEYS = ("name", "centre", "half_extents", "rpy")
OBSTACLE_KEYS = {"box": ("name", "kind", "centre", "half_extents", "rpy"),
                 "plane": ("name", "kind", "point", "normal")}  # fmt: skip
CELL_KEYS = ("obstacles",)
#: m: the bounds of ``clearance`` (0: contact only; 1 m: no cell is that roomy)
CLEARANCE_RANGE = (0.0, 1.0)


@dataclass(frozen=True)
class Box:
    """A box: ``centre`` (m), ``half_extents`` (m, > 0, along the box's own axes) and
    ``rotation`` (box axes → the frame it is given in: the platform's for a body, the base's
    for an obstacle)."""

    name: str
    centre: FloatArray
    half_extents: FloatArray
    rotation: FloatArray


@dataclass(frozen=True)
class Plane:
    """A half-space obstacle (a floor, a wall, a facade), base frame: the solid side is behind
    ``point`` against the unit ``normal``, which points into the free space."""

    name: str
    point: FloatArray
    normal: FloatArray


@dataclass(frozen=True)
class InterferenceConfig:
    # m: the least distance allowed between two cables, a cable and the platform's body, a
    # cable and an obstacle
    clearance: float = 0.005
    # m: a cable is measured against the platform's body from this far along it from its
    # attachment (the eyelet, the bracket the attachment stands on are not a contact). A cable
    # leaving its attachment at an angle θ to a face of the body is there ``e sin θ`` from it:
    # at 5 cm and a 5 mm clearance, one within 5.7° of a face is too close
    attachment_exclusion: float = 0.05
    body: tuple[Box, ...] = ()  # platform frame
    obstacles: tuple[Box | Plane, ...] = field(default_factory=tuple)  # base frame


def read_interference(rd: TableReader, data: dict[str, Any]) -> InterferenceConfig:
    """``[interference]``, ``[platform.body]`` and ``[[cell.obstacles]]``. Errors go to ``rd``
    (one line each: the key, the value, the unit, the rule)."""
    d = InterferenceConfig()
    t = rd.table(data, "interference", "", required=False) or {}
    rd.check_keys(t, INTERFERENCE_KEYS, "interference")
    lo, hi = CLEARANCE_RANGE
    clearance = rd.number(t, "clearance", "interference", "m", required=False,
                          default=d.clearance, minimum=lo, maximum=hi)  # fmt: skip
    exclusion = rd.number(t, "attachment_exclusion", "interference", "m", required=False,
                          default=d.attachment_exclusion, minimum=0.0, maximum=hi)  # fmt: skip
    platform = data.get("platform")
    body: list[Box] = []
    if isinstance(platform, dict):
        bt = rd.table(platform, "body", "platform", required=False) or {}
        rd.check_keys(bt, BODY_KEYS, "platform.body")
        boxes = _tables(rd, bt, "boxes", "platform.body")
        _unique_names(rd, boxes, "platform.body.boxes", "box")
        for k, raw in enumerate(boxes):
            box = _box(rd, raw, f"platform.body.boxes[{k}]", BOX_KEYS, unnamed("box", k))
            if box is not None:
                body.append(box)
    obstacles: list[Box | Plane] = []
    cell = rd.table(data, "cell", "", required=False) or {}
    rd.check_keys(cell, CELL_KEYS, "cell")
    tables = _tables(rd, cell, "obstacles", "cell")
    _unique_names(rd, tables, "cell.obstacles", "obstacle")
    for k, raw in enumerate(tables):
        obstacle = _obstacle(rd, raw, f"cell.obstacles[{k}]", unnamed("obstacle", k))
        if obstacle is not None:
            obstacles.append(obstacle)
    if clearance is None or exclusion is None:
        return d  # the errors are in ``rd``
    return InterferenceConfig(clearance, exclusion, tuple(body), tuple(obstacles))


def unnamed(kind: str, k: int) -> str:
    """The name of the ``k``-th (from 0) ``kind`` given without one: "obstacle 2"."""
    return f"{kind} {k + 1}"


def _unique_names(rd: TableReader, tables: list[dict[str, Any]], path: str, kind: str) -> None:
    """Each name once among ``tables`` (messages name a shape by it: two alike would say one
    where the other is meant); an unnamed one is called "``kind`` N", N its place from 1."""
    seen: dict[str, int] = {}
    for k, t in enumerate(tables):
        name = t.get("name", unnamed(kind, k))
        if not isinstance(name, str):
            continue  # its own error, from the reader
        if name in seen:
            rd.error(f"{path}[{k}].name", name, "", f"must differ from {path}[{seen[name]}]'s: "
                     f"messages name each by it (one without a name is '{kind} N', N its place "
                     "from 1)")  # fmt: skip
        seen.setdefault(name, k)


def _tables(rd: TableReader, parent: dict[str, Any], key: str, path: str) -> list[dict[str, Any]]:
    raw = parent.get(key, [])
    if not isinstance(raw, list) or not all(isinstance(x, dict) for x in raw):
        rd.error(f"{path}.{key}", raw, "", f"must be an array of tables [[{path}.{key}]]")
        return []
    return raw


def _box(rd: TableReader, t: dict[str, Any], path: str, keys: tuple[str, ...],
         default_name: str) -> Box | None:  # fmt: skip
    rd.check_keys(t, keys, path)
    name = rd.string(t, "name", path, required=False, default=default_name)
    centre = rd.vector(t, "centre", path, "m")
    half = rd.vector(t, "half_extents", path, "m")
    rpy = rd.rpy(t, "rpy", path)
    if half is not None and not np.all(half > 0.0):
        rd.error(f"{path}.half_extents", half, "m", "must all be > 0 (m: half the box's sides)")
        half = None
    if name is None or centre is None or half is None or rpy is None:
        return None
    return Box(name, centre, half, rpy_to_matrix(float(rpy[0]), float(rpy[1]), float(rpy[2])))


def _obstacle(rd: TableReader, t: dict[str, Any], path: str,
              default_name: str) -> Box | Plane | None:  # fmt: skip
    kind = rd.string(t, "kind", path)
    if kind is None:
        return None
    if kind not in OBSTACLE_KEYS:
        rd.error(f"{path}.kind", kind, "", "must be one of 'box', 'plane'")
        return None
    if kind == "box":
        return _box(rd, t, path, OBSTACLE_KEYS["box"], default_name)
    rd.check_keys(t, OBSTACLE_KEYS["plane"], path)
    name = rd.string(t, "name", path, required=False, default=default_name)
    point = rd.vector(t, "point", path, "m")
    normal = rd.vector(t, "normal", path, "")
    if normal is not None:
        norm = float(np.linalg.norm(normal))
        if norm < 1e-9:
            rd.error(f"{path}.normal", normal, "", "must be a non-zero vector (towards the free "
                     "side of the plane)")  # fmt: skip
            normal = None
        else:
            normal = normal / norm
    if name is None or point is None or normal is None:
        return None
    return Plane(name, point, normal)
