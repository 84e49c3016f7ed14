"""The ``[[cables]]`` tables of a robot description and their winches (``[winch]`` and each
cable's ``[cables.winch]``) and pulleys, read and checked; every problem reported through the
``TableReader`` (``docs/config.md``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from cdprctl.model.reader import TableReader
from cdprctl.model.robot import Cable, Pulley, Winch

WINCH_KEYS = (
    "drum_radius",
    "gear_ratio",
    "rotor_inertia",
    "viscous_friction",
    "coulomb_friction",
    "stribeck_friction",
    "pulley_friction",
    "torque_limit",
    "encoder_counts_per_rev",
)
CABLE_KEYS = (
    "name",
    "anchor",
    "attachment",
    "tension_min",
    "tension_max",
    "stiffness",
    "youngs_modulus",
    "cross_section",
    "spring_stiffness",
    "damping",
    "length_to_winch",
    "pulley",
    "winch",
)
PULLEY_KEYS = ("radius", "axis")

# (key, unit, rule keywords) of the [winch] table.
_WINCH_FIELDS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("drum_radius", "m", {"positive": True}),
    ("gear_ratio", "", {"positive": True}),
    ("rotor_inertia", "kg·m²", {"minimum": 0.0}),
    ("viscous_friction", "N·m·s/rad", {"minimum": 0.0}),
    ("coulomb_friction", "N·m", {"minimum": 0.0}),
    # the breakaway friction beyond the Coulomb level near zero speed (numerics.friction_law)
    ("stribeck_friction", "N·m", {"minimum": 0.0, "required": False, "default": 0.0}),
    # μ of the capstan loss of the cable over its swivel pulley (a robot without pulleys: none)
    ("pulley_friction", "", {"minimum": 0.0, "maximum": 1.0, "required": False, "default": 0.0}),
    ("torque_limit", "N·m", {"positive": True}),
    ("encoder_counts_per_rev", "counts", {"positive": True, "integer": True}),
)


def read_winch(rd: TableReader, t: dict[str, Any], path: str, base: Winch | None) -> Winch | None:
    """Read a winch table; keys it does not give are taken from ``base`` (the global one)."""
    rd.check_keys(t, WINCH_KEYS, path)
    values: dict[str, float | None] = {}
    for key, unit, rules in _WINCH_FIELDS:
        if key in t or base is None:
            values[key] = rd.number(t, key, path, unit, **rules)
        else:
            values[key] = float(getattr(base, key))
    numbers = {k: v for k, v in values.items() if v is not None}
    if len(numbers) != len(values):
        return None
    return Winch(
        drum_radius=numbers["drum_radius"],
        gear_ratio=numbers["gear_ratio"],
        rotor_inertia=numbers["rotor_inertia"],
        viscous_friction=numbers["viscous_friction"],
        coulomb_friction=numbers["coulomb_friction"],
        stribeck_friction=numbers["stribeck_friction"],
        pulley_friction=numbers["pulley_friction"],
        torque_limit=numbers["torque_limit"],
        encoder_counts_per_rev=int(numbers["encoder_counts_per_rev"]),
    )


def read_cables(
    rd: TableReader, data: dict[str, Any], has_winch_table: bool, default_winch: Winch | None
) -> list[Cable] | None:
    raw = data.get("cables")
    if raw is None:
        rd.error_missing("cables", "", "an array of tables [[cables]], one per cable")
        return None
    if not isinstance(raw, list) or not all(isinstance(c, dict) for c in raw):
        rd.error("cables", raw, "", "must be an array of tables [[cables]]")
        return None
    if len(raw) < 6:
        rd.errors.append(
            f"{rd.file}: cables has {len(raw)} entries: a 6-DOF platform needs at least 6 cables"
        )
    cables: list[Cable] = []
    names: dict[str, int] = {}
    ok = True
    for i, ct in enumerate(raw):
        path = f"cables[{i}]"
        name = ct.get("name", str(i + 1))
        if isinstance(name, str) and name in names:
            rd.error(
                f"{path}.name",
                name,
                "",
                f"duplicates the name of cables[{names[name]}]: names must be unique",
            )
            ok = False
        elif isinstance(name, str):
            names[name] = i
        cable = read_cable(rd, ct, path, i, has_winch_table, default_winch)
        if cable is None:
            ok = False
        else:
            cables.append(cable)
    return cables if ok else None


def read_cable(
    rd: TableReader,
    t: dict[str, Any],
    path: str,
    index: int,
    has_winch_table: bool,
    default_winch: Winch | None,
) -> Cable | None:
    rd.check_keys(t, CABLE_KEYS, path)
    n_errors = len(rd.errors)
    name = rd.string(t, "name", path, required=False, default=str(index + 1))
    anchor = rd.vector(t, "anchor", path, "m")
    attachment = rd.vector(t, "attachment", path, "m")
    t_min = rd.number(t, "tension_min", path, "N", minimum=0.0)
    t_max = rd.number(t, "tension_max", path, "N", positive=True)
    if t_min is not None and t_max is not None and t_min >= t_max:
        rd.error(f"{path}.tension_min", t_min, "N", f"exceeds tension_max = {t_max:g} N")
    stiffness = rd.number(t, "stiffness", path, "N/m", required=False, positive=True)
    modulus = rd.number(t, "youngs_modulus", path, "Pa", required=False, positive=True)
    section = rd.number(t, "cross_section", path, "m²", required=False, positive=True)
    _elasticity_given_once(rd, t, path)
    spring = rd.number(t, "spring_stiffness", path, "N/m", required=False, positive=True)
    damping = rd.number(t, "damping", path, "N·s/m", required=False, default=0.0, minimum=0.0)
    to_winch = rd.number(t, "length_to_winch", path, "m", required=False, default=0.0, minimum=0.0)
    pulley = None
    pt = rd.table(t, "pulley", path, required=False)
    if pt is not None:
        pulley = read_pulley(rd, pt, f"{path}.pulley")
    winch = _cable_winch(rd, t, path, has_winch_table, default_winch)
    if winch is not None and t_max is not None and t_max > winch.max_cable_force * (1 + 1e-12):
        rd.error(
            f"{path}.tension_max",
            t_max,
            "N",
            f"exceeds what the winch can hold, torque_limit·gear_ratio/drum_radius = "
            f"{winch.max_cable_force:.4g} N",
        )
    if (
        len(rd.errors) > n_errors
        or name is None
        or anchor is None
        or attachment is None
        or t_min is None
        or t_max is None
        or damping is None
        or to_winch is None
        or winch is None
    ):
        return None
    return Cable(
        name=name,
        anchor=anchor,
        attachment=attachment,
        tension_min=t_min,
        tension_max=t_max,
        stiffness=stiffness,
        youngs_modulus=modulus,
        cross_section=section,
        spring_stiffness=spring,
        damping=damping,
        length_to_winch=to_winch,
        pulley=pulley,
        winch=winch,
    )


def _elasticity_given_once(rd: TableReader, t: dict[str, Any], path: str) -> None:
    """A cable's elasticity: a fixed stiffness, or both a Young's modulus and a section."""
    has_k, has_e, has_s = "stiffness" in t, "youngs_modulus" in t, "cross_section" in t
    if has_k and (has_e or has_s):
        rd.errors.append(
            f"{rd.file}: {path} gives both stiffness and youngs_modulus/cross_section: "
            "give either a fixed stiffness (N/m) or both youngs_modulus (Pa) and cross_section (m²)"
        )
    elif not has_k and not (has_e and has_s):
        missing = "cross_section" if has_e else "youngs_modulus" if has_s else "stiffness"
        rd.errors.append(
            f"{rd.file}: {path}.{missing} is missing: elasticity needs stiffness (N/m), "
            "or both youngs_modulus (Pa) and cross_section (m²)"
        )


def _cable_winch(rd: TableReader, t: dict[str, Any], path: str, has_winch_table: bool,
                 default_winch: Winch | None) -> Winch | None:  # fmt: skip
    """The cable's own ``[cables.winch]`` over the global ``[winch]`` (``default_winch``),
    or the global one; None where neither is usable (reported)."""
    winch_table = rd.table(t, "winch", path, required=False)
    winch: Winch | None = None
    if winch_table is None and not has_winch_table:
        rd.error_missing(f"{path}.winch", "", "a [winch] table (global or per cable)")
    elif winch_table is None:
        winch = default_winch  # None when [winch] itself was invalid (reported there)
    elif default_winch is not None or not has_winch_table:
        winch = read_winch(rd, winch_table, f"{path}.winch", default_winch)
    return winch


def read_pulley(rd: TableReader, t: dict[str, Any], path: str) -> Pulley | None:
    rd.check_keys(t, PULLEY_KEYS, path)
    radius = rd.number(t, "radius", path, "m", positive=True)
    axis = rd.vector(t, "axis", path, "(unit vector)")
    if axis is not None:
        norm = float(np.linalg.norm(axis))
        if norm < 1e-9:
            rd.error(f"{path}.axis", axis, "", "must not be the zero vector")
            axis = None
        else:
            axis = axis / norm
    if radius is None or axis is None:
        return None
    return Pulley(radius=radius, axis=axis)
