"""The last brake test, kept in the state directory beside the calibration record
(``brake_test.json``, written atomically), and whether a real robot may be enabled: its last
test passed and is younger than ``[safety] brake_test_interval``."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cdprctl.core.state_file import iso_utc, read_json, write_json
from cdprctl.model.robot import RobotModel

FILE_NAME = "brake_test.json"
FORMAT = 1


@dataclass
class CableResult:
    cable: str
    passed: bool
    torque: float  # N·m at the motor: the test torque asked (in the pay-out direction)
    applied: float  # N·m: the largest torque the drive reported applying (its 0x6077)
    motion: float  # rad at the motor: the largest motion seen under it
    counts: float  # that motion in encoder counts
    capped: bool  # the test torque was the drive's limit, below the configured one
    stopped_early: bool = False  # the motion passed its bound: the torque taken off at once


@dataclass
class BrakeTestRecord:
    robot: str
    time: str  # ISO 8601, UTC
    unix_time: float  # s since the epoch (the interval's reference)
    passed: bool
    max_counts: int  # the bound each cable was held to
    cables: list[CableResult] = field(default_factory=list)
    identities: list[Any] = field(default_factory=list)  # the drives' 0x1018, where known
    simulated: bool = False  # run on the simulated robot: never a real robot's brake test

    def summary(self) -> dict[str, Any]:
        """What ``cdprctl brake-test --json`` prints."""
        return {
            "passed": self.passed,
            "time": self.time,
            "cables": [dataclasses.asdict(c) for c in self.cables],
        }


class BrakeTestError(Exception):
    """No usable brake test: missing, unreadable, failed or too old; the message says which."""


def record_path(state_dir: Path) -> Path:
    return Path(state_dir) / FILE_NAME


def save(record: BrakeTestRecord, state_dir: Path) -> Path:
    return write_json(record_path(state_dir), FORMAT, record)


def load(state_dir: Path) -> BrakeTestRecord:
    path = record_path(state_dir)
    data = read_json(path, FORMAT, "brake test record", BrakeTestError)
    try:
        cables = [CableResult(**c) for c in data.pop("cables")]
        return BrakeTestRecord(cables=cables, **data)
    except (TypeError, KeyError) as exc:
        raise BrakeTestError(f"{path}: {exc}") from None


def check_due(model: RobotModel, state_dir: Path, now: float,
              simulated: bool = False) -> BrakeTestRecord:  # fmt: skip
    """The last brake test of ``model``, if it allows an enable at ``now`` (s since the
    epoch): passed, for this robot, within ``[safety] brake_test_interval``, and of a real
    robot unless the robot enabled is ``simulated``; :class:`BrakeTestError` otherwise."""
    record = load(state_dir)
    if record.robot != model.name:
        raise BrakeTestError(f"the brake test on record is of robot {record.robot!r}, not "
                             f"{model.name!r}")  # fmt: skip
    if record.simulated and not simulated:
        raise BrakeTestError(f"the brake test on record ({record.time}) was run on the "
                             "simulated robot, not on these brakes")  # fmt: skip
    if not record.passed:
        failed = ", ".join(c.cable for c in record.cables if not c.passed)
        raise BrakeTestError(f"the last brake test ({record.time}) failed on cable(s) {failed}")
    age = now - record.unix_time
    interval = model.safety.brake_test_interval
    if age < 0.0:
        raise BrakeTestError(
            f"the last brake test is dated {record.time}, after this machine's clock: set "
            "the clock, then test the brakes again"
        )
    if age > interval:
        raise BrakeTestError(
            f"the last brake test ({record.time}) is {age / 3600.0:.1f} h old, beyond "
            f"[safety] brake_test_interval = {interval:g} s ({interval / 3600.0:.1f} h)"
        )
    return record


def check_drives(record: BrakeTestRecord, identities: list[Any], names: list[str]) -> None:
    """With the drives configured: the same drives as those tested (0x1018, where both have
    it): a brake test is of the brakes on these winches; :class:`BrakeTestError` otherwise."""
    for i, (then, now) in enumerate(zip(record.identities, identities, strict=False)):
        if then and now and then != now:
            raise BrakeTestError(
                f"the drive of cable {names[i]} is not the one whose brake was tested "
                f"(identity 0x1018 {now}, the brake test has {then}): a drive was exchanged"
            )


def due_time(record: BrakeTestRecord, model: RobotModel) -> str:
    """ISO time (UTC) the next brake test after ``record`` is due."""
    return iso_utc(record.unix_time + model.safety.brake_test_interval)


def how_to_test(model: RobotModel, state_dir: Path, bus: str = "") -> str:
    """The command that tests the brakes (``bus``: the bus options the run was given)."""
    config = model.source_file or "ROBOT.toml"
    return (f"test the brakes: cdprctl brake-test --config {config} --state-dir {state_dir}"
            + (f" {bus}" if bus else ""))  # fmt: skip
