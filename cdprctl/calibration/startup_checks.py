"""What ``cdprctl run`` does with the calibration record at start-up: load it (refuse when it
is missing or does not fit the robot) before the drives are touched, then, with the drives
configured, refuse when their identities differ or when one was reset since cdprctl last set
it up (an incremental counter restarted), else hand the offsets to the estimator. The forward
kinematics' residual at start-up (``Controller.initialise``) catches encoders that fit no
pose (docs/homing.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cdprctl.calibration.calibration_record import (
    CalibrationError,
    CalibrationRecord,
    identities_of,
    load,
)
from cdprctl.model.robot import RobotModel
from drivers.base import WinchDriver


def how_to_calibrate(model: RobotModel, state_dir: Path, bus: str = "") -> str:
    """The command that calibrates (``bus``: the bus options the run was given)."""
    config = model.source_file or "ROBOT.toml"
    return (
        f"calibrate: cdprctl calibrate --config {config} --state-dir {state_dir} "
        + (f"{bus} " if bus else "")
        + "known-pose (the platform on its home fixture) or ... self (near home); or, for the "
        "simulated robot started at home only, [drives] assume_home_at_start = true"
    )


def load_record(model: RobotModel, state_dir: Path, simulated: bool = False) -> CalibrationRecord:
    """The record for ``model`` in ``state_dir``; :class:`CalibrationError` otherwise (a real
    robot, not ``simulated``, never takes a simulated robot's record)."""
    record = load(state_dir)
    record.check(model)
    if record.simulated and not simulated:
        raise CalibrationError(f"the calibration on record ({record.time}) was taken on a "
                               "simulated robot, not on these drives")  # fmt: skip
    return record


def check_drives(model: RobotModel, record: CalibrationRecord, driver: WinchDriver) -> None:
    """With the drives configured: the same drives as at calibration (0x1018, where both
    have it) and, with incremental encoders, none reset since cdprctl last set it up."""
    names = [c.name for c in model.cables]
    now = identities_of(driver, model.n_cables)
    for i, (then, ident) in enumerate(zip(record.identities, now, strict=False)):
        if then and ident and then != ident:
            raise CalibrationError(
                f"the drive of cable {names[i]} is not the one calibrated with (identity "
                f"0x1018 {ident}, the record has {then}): a drive was exchanged"
            )
    if model.drives.encoders == "absolute":
        return
    reset = driver.reset_since_setup
    if reset is None:
        raise CalibrationError(
            f"the {model.drives.driver} driver cannot tell whether a drive was reset since "
            "the calibration, and the encoders are incremental ([drives] encoders): declare "
            "absolute encoders if they are"
        )
    if any(reset):
        which = ", ".join(names[i] for i, r in enumerate(reset) if r)
        raise CalibrationError(
            f"the drives of cables {which} were reset (power-up or NMT reset) since cdprctl "
            "last set them up: their incremental encoders lost their zero"
        )


def offsets(record: CalibrationRecord) -> tuple[np.ndarray, np.ndarray]:
    """(theta_zero rad, drum_scale) for ``Estimator.apply_calibration``."""
    return np.array(record.theta_zero, float), np.array(record.drum_scale, float)
