"""The calibration record: per cable, the motor angle at which its unstretched length is its
length at the home pose (``theta_zero``, rad) and its drum's pay-out scale, with where it came
from. Kept as JSON in the robot's state directory, written atomically (docs/homing.md)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from pathlib import Path
from typing import Any

from cdprctl.core.state_dir import default_state_dir
from cdprctl.core.state_file import iso_utc, read_dataclass, write_json
from cdprctl.model.robot import RobotModel

__all__ = ["default_state_dir"]  # re-exported: where the daemon and the commands look

FILE_NAME = "calibration.json"
FORMAT = 1


class CalibrationError(Exception):
    """A record that is missing, unreadable or does not fit the robot: the message says what
    and how to calibrate."""


def geometry_hash(model: RobotModel) -> str:
    """sha256 of what a calibration depends on: anchors, attachments, pulleys, drums, gears,
    encoders, the cables' elasticity and the home pose. Gains, limits and buses may change
    without invalidating a record."""
    cables = [
        {
            "anchor": [round(float(x), 9) for x in c.anchor],
            "attachment": [round(float(x), 9) for x in c.attachment],
            "pulley": None if c.pulley is None else [c.pulley.radius, *map(float, c.pulley.axis)],
            "drum_radius": c.winch.drum_radius,
            "gear_ratio": c.winch.gear_ratio,
            "counts_per_rev": c.winch.encoder_counts_per_rev,
            "elastic": [c.stiffness, c.youngs_modulus, c.cross_section, c.spring_stiffness,
                        c.length_to_winch],
        }
        for c in model.cables
    ]  # fmt: skip
    home = [*map(float, model.home.position), *map(float, model.home.rpy)]
    text = json.dumps({"cables": cables, "home": home}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@dataclasses.dataclass
class CalibrationRecord:
    robot: str
    method: str  # "known-pose" or "self"
    time: str  # ISO 8601, UTC
    geometry_hash: str
    encoders: str  # "incremental" or "absolute", as the config declared at calibration
    theta_zero: list[float]  # rad, motor side, per cable
    drum_scale: list[float]  # per cable (1: the config's drum radius)
    pose: list[float]  # x, y, z (m), roll, pitch, yaw (rad): the pose calibrated at
    identities: list[dict[str, int] | None]  # each drive's 0x1018, where it has one
    residual_rms: float | None = None  # m, of the identification's length residuals
    condition: float | None = None  # of the identification Jacobian
    std: list[float] | None = None  # m, rad: predicted standard deviation of the pose
    samples: int = 1
    sample_residuals: list[float] = dataclasses.field(default_factory=list)  # m, RMS each
    notes: dict[str, Any] = dataclasses.field(default_factory=dict)
    simulated: bool = False  # taken on a simulated robot: never a real robot's calibration
    # ``cdprctl calibrate friction``'s result (calibration/friction_record.py): each winch's
    # terms, applied by the next ``run`` in place of the robot file's
    friction: dict[str, Any] | None = None

    def check(self, model: RobotModel) -> None:
        """Raise :class:`CalibrationError` when the record does not fit ``model``."""
        m = model.n_cables
        if self.robot != model.name:
            raise CalibrationError(f"the record is for robot {self.robot!r}, not {model.name!r}")
        for name in ("theta_zero", "drum_scale"):
            values = getattr(self, name)
            if len(values) != m or not all(math.isfinite(v) for v in values):
                raise CalibrationError(f"{name}: {values} is not {m} finite numbers")
        if not all(0.9 < s < 1.1 for s in self.drum_scale):
            raise CalibrationError(f"drum_scale: {self.drum_scale} outside (0.9, 1.1)")
        for name in ("viscous", "coulomb", "stribeck", "pulley") if self.friction else ():
            values = self.friction.get(name) if self.friction else None
            if (not isinstance(values, list) or len(values) != m
                    or not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0
                               for v in values)):  # fmt: skip
                raise CalibrationError(f"friction.{name}: {values} is not {m} finite numbers "
                                       ">= 0 (N·m·s/rad, N·m, N·m, μ)")  # fmt: skip
        if self.geometry_hash != geometry_hash(model):
            raise CalibrationError(
                f"the robot's geometry changed since the calibration of {self.time} (hash "
                f"{self.geometry_hash}, now {geometry_hash(model)}: anchors, attachments, "
                "drums, encoders, elasticity or home)"
            )


def stamped(model: RobotModel, method: str, **fields: Any) -> CalibrationRecord:
    """A record of ``model`` by ``method``, stamped now with what it holds for (the robot's
    name, its geometry's hash, its encoders' kind as the config declares them); ``fields``
    the rest (``CalibrationRecord``)."""
    return CalibrationRecord(robot=model.name, method=method, time=now_iso(),
                             geometry_hash=geometry_hash(model),
                             encoders=model.drives.encoders, **fields)  # fmt: skip


def identities_of(driver: Any, n_cables: int) -> list[dict[str, int] | None]:
    """Each drive's identity (0x1018) as the driver read it, None where it has none."""
    return list(getattr(driver, "identities", [None] * n_cables))


def record_path(state_dir: Path) -> Path:
    return Path(state_dir) / FILE_NAME


def now_iso() -> str:
    return iso_utc()


def save(record: CalibrationRecord, state_dir: Path) -> Path:
    """Written atomically (``state_file.write_json``)."""
    return write_json(record_path(Path(state_dir)), FORMAT, record)


def load(state_dir: Path) -> CalibrationRecord:
    """The record in ``state_dir``; :class:`CalibrationError` saying what is wrong."""
    return read_dataclass(CalibrationRecord, record_path(state_dir), FORMAT, "calibration record",
                          CalibrationError)  # fmt: skip
