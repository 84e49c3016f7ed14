"""A friction calibration in the calibration record (``CalibrationRecord.friction``): written
by ``cdprctl calibrate friction``, applied by ``cdprctl run`` to the torque law and the tension
estimate in place of the robot file's winch terms (docs/friction.md)."""

from __future__ import annotations

from typing import Any

from cdprctl.calibration.calibration_record import CalibrationRecord, now_iso
from cdprctl.calibration.friction import WinchFriction
from cdprctl.model.robot import RobotModel


def friction_entry(model: RobotModel, fits: list[WinchFriction], motion_time: float,
                   simulated: bool) -> dict[str, Any]:  # fmt: skip
    """The record's ``friction``: per winch (the robot file's order) the identified terms,
    their σ, the pulley's μ (the file's where the data did not decide it) and the residual."""
    files = [c.winch for c in model.cables]
    return {
        "time": now_iso(),
        "simulated": simulated,
        "motion_time": motion_time,
        "viscous": [stored_terms(f)[0] for f in fits],  # N·m·s/rad
        "coulomb": [stored_terms(f)[1] for f in fits],  # N·m
        "stribeck": [stored_terms(f)[2] for f in fits],  # N·m
        "pulley": [
            f.pulley if f.pulley is not None else w.pulley_friction
            for f, w in zip(fits, files, strict=True)
        ],
        "pulley_identified": [f.pulley is not None for f in fits],
        "inertia": [f.inertia for f in fits],  # kg·m², what the drive accelerates
        "std": [list(f.std) for f in fits],  # viscous, Coulomb, Stribeck, inertia
        "residual_rms": [f.residual_rms for f in fits],  # N·m
    }


def stored_terms(f: WinchFriction) -> tuple[float, float, float]:
    """(viscous, Coulomb, Stribeck) of a fit as the record keeps them and the command prints
    them: a term below zero (within its noise: ``friction.refusal`` refuses one beyond 3 σ)
    is kept as 0. The law's friction never pushes the motion on: a negative Coulomb or
    viscous term would, and a negative Stribeck term (a breakaway below the Coulomb level)
    is not the law's and, fed forward, would push the drive below its Coulomb level at
    every start."""
    return max(0.0, f.viscous), max(0.0, f.coulomb), max(0.0, f.stribeck)


def clipped_note(f: WinchFriction) -> str:
    """The one line that says which fitted terms came out below zero and are kept as 0 (""
    when none did)."""
    neg = [f"{name} {x:.3g} ± {sd:.2g}" for name, x, sd in
           (("viscous", f.viscous, f.std[0]), ("Coulomb", f.coulomb, f.std[1]),
            ("Stribeck", f.stribeck, f.std[2])) if x < 0.0]  # fmt: skip
    return (f"fitted {', '.join(neg)} below zero, kept as 0 (friction never drives the "
            "motion)") if neg else ""


def friction_terms(record: CalibrationRecord) -> tuple[list[float], ...] | None:
    """(viscous, coulomb, stribeck, pulley) per winch from the record, None without one."""
    f = record.friction
    if not f:
        return None
    return f["viscous"], f["coulomb"], f["stribeck"], f["pulley"]


def friction_line(record: CalibrationRecord) -> str:
    """The friction in use, in one line (``run``'s start-up)."""
    f = record.friction
    if not f:
        return "friction: the robot file's (no friction calibration on record)"
    c, v = f["coulomb"], f["viscous"]
    return (f"friction: identified {f['time']} (Coulomb {min(c):.3g}..{max(c):.3g} N·m, "
            f"viscous {min(v):.3g}..{max(v):.3g} N·m·s/rad per winch)")


def friction_summary(model: RobotModel, state_dir: Any) -> dict[str, Any]:
    """What the gateway's status says of the friction in use: the calibration's (its time,
    per winch its terms) where the record in ``state_dir`` has one, else the robot file's."""
    from cdprctl.calibration.calibration_record import CalibrationError, load

    try:
        rec = load(state_dir)
    except CalibrationError:
        rec = None
    f = rec.friction if rec is not None and rec.robot == model.name else None
    if f:
        return {"source": "calibrated", "time": f["time"], "viscous": f["viscous"],
                "coulomb": f["coulomb"], "stribeck": f["stribeck"],
                "pulley": f["pulley"]}  # fmt: skip
    w = [c.winch for c in model.cables]
    return {"source": "file", "time": None, "viscous": [x.viscous_friction for x in w],
            "coulomb": [x.coulomb_friction for x in w],
            "stribeck": [x.stribeck_friction for x in w],
            "pulley": [x.pulley_friction for x in w]}  # fmt: skip
