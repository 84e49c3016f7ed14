"""The ``[[grippers]]`` section: the reconfigurable end-effector of Sensors 2019, 19, 3403, §2.4.

A gripper hangs on one cable ``j``. That cable's ``stiffness`` is the spring ``K_A`` between the
(inextensible) cable and the platform — the paper's model, where the 1000 N/m "cable stiffness"
is that spring — and the cable splits at the spring's end into ``jA`` (through ``K_A`` to the
attachment point ``p_j``) and ``jB``, which runs over a small pulley at ``p_j`` and then along
the guide to the jaw. Pulling the cable stretches ``K_A`` by ``δ`` and moves the jaw by the same
``δ`` along ``guide_axis`` (eq. (25)); after ``free_travel`` (``L21``) the jaw meets the object and
squeezes it through ``K_B`` (eq. (40), (43)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprctl.core.rotation import FloatArray
from cdprctl.model.reader import TableReader

GRIPPER_KEYS = (
    "cable",
    "jaw_mass",
    "jaw_offset",
    "guide_axis",
    "k_b",
    "free_travel",
    "object_stiffness",
    "guide_friction",
    "travel_max",
)


@dataclass(frozen=True)
class Gripper:
    cable: int  # index of the cable that carries it
    name: str  # that cable's name
    jaw_mass: float  # kg
    jaw_offset: FloatArray  # m, platform frame: L1^M, attachment → jaw at zero travel
    guide_axis: FloatArray  # unit, platform frame: k̂_M, the way jB pulls the jaw (closing)
    k_b: float  # N/m, the squeezing spring K_B
    free_travel: float  # m, L21: travel at which the jaw meets the object (the sim's object)
    object_stiffness: float  # N/m, the object's own stiffness, in series with K_B (inf: rigid)
    guide_friction: float  # N, Coulomb friction of the jaw on its guide (the paper's F_jBA)
    travel_max: float  # m, the guide's upper end stop (the lower one is at zero travel)


def in_series(k1: float, k2: float) -> float:
    """Stiffness (N/m) of two springs in series; an infinite one is rigid."""
    if math.isinf(k2):
        return k1
    if math.isinf(k1):
        return k2
    return 1.0 / (1.0 / k1 + 1.0 / k2)


def read_grippers(
    rd: TableReader, data: dict[str, Any], cables: list[Any] | None
) -> tuple[Gripper, ...] | None:
    raw = data.get("grippers")
    if raw is None:
        return ()
    if not isinstance(raw, list) or not all(isinstance(g, dict) for g in raw):
        rd.error("grippers", raw, "", "must be an array of tables [[grippers]]")
        return None
    if cables is None:
        return None
    out: list[Gripper] = []
    n_errors = len(rd.errors)
    if len(raw) > len(cables) - 6:
        rd.errors.append(
            f"{rd.file}: grippers has {len(raw)} entries: at most r = m − 6 = {len(cables) - 6} "
            "grippers can be moved by the redundancy without moving the platform "
            "(Sensors 2019 §2.4)"
        )
    used: dict[str, int] = {}
    for i, g in enumerate(raw):
        path = f"grippers[{i}]"
        rd.check_keys(g, GRIPPER_KEYS, path)
        name, idx = _gripper_cable(rd, g, i, cables, used)
        mass = rd.number(g, "jaw_mass", path, "kg", positive=True)
        offset = rd.vector(g, "jaw_offset", path, "m")
        axis = rd.vector(g, "guide_axis", path, "")
        if axis is not None and np.linalg.norm(axis) < 1e-9:
            rd.error(f"{path}.guide_axis", axis, "", "must be a non-zero vector")
            axis = None
        k_b = rd.number(g, "k_b", path, "N/m", positive=True)
        free = rd.number(g, "free_travel", path, "m", positive=True)
        k_obj = rd.number(
            g, "object_stiffness", path, "N/m", required=False, default=math.inf, positive=True
        )
        friction = rd.number(
            g, "guide_friction", path, "N", required=False, default=0.0, minimum=0.0
        )
        travel_max = rd.number(g, "travel_max", path, "m", positive=True)
        if free is not None and travel_max is not None and travel_max <= free:
            rd.error(
                f"{path}.travel_max",
                travel_max,
                "m",
                f"must exceed free_travel = {free:g} m: the object sits inside the guide",
            )
        if len(rd.errors) > n_errors or any(
            v is None for v in (idx, mass, offset, axis, k_b, free, travel_max)
        ):
            continue
        assert name is not None and idx is not None and axis is not None
        out.append(
            Gripper(
                cable=idx,
                name=name,
                jaw_mass=float(mass),  # type: ignore[arg-type]
                jaw_offset=offset,  # type: ignore[arg-type]
                guide_axis=axis / np.linalg.norm(axis),
                k_b=float(k_b),  # type: ignore[arg-type]
                free_travel=float(free),  # type: ignore[arg-type]
                object_stiffness=float(k_obj),  # type: ignore[arg-type]
                guide_friction=float(friction),  # type: ignore[arg-type]
                travel_max=float(travel_max),  # type: ignore[arg-type]
            )
        )
    return tuple(out) if len(rd.errors) == n_errors else None


def _gripper_cable(rd: TableReader, g: dict[str, Any], i: int, cables: list[Any],
                   used: dict[str, int]) -> tuple[str | None, int | None]:  # fmt: skip
    """The cable (name, index) gripper ``i`` hangs on: a cable that carries no other
    (``used``: the grippers' indices by cable, updated) and has the paper's model, a fixed
    stiffness K_A."""
    names, path = [c.name for c in cables], f"grippers[{i}]"
    name = rd.string(g, "cable", path)
    idx = None
    if name is not None and name not in names:
        rd.error(f"{path}.cable", name, "", f"is not a cable ({', '.join(names)})")
    elif name is not None and name in used:
        rd.error(f"{path}.cable", name, "", f"already carries grippers[{used[name]}]")
    elif name is not None:
        used[name] = i
        idx = names.index(name)
        c = cables[idx]
        if c.stiffness is None or c.spring_stiffness is not None:
            rd.errors.append(
                f"{rd.file}: cables[{idx}] (name {name!r}) carries {path}: it must give a "
                "fixed stiffness (N/m), the spring K_A, and no spring_stiffness or "
                "youngs_modulus (the paper's model: an inextensible cable and K_A)"
            )
    return name, idx
