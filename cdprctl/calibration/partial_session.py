"""A long procedure stopped midway keeps what it measured: the partial session, a file in the
robot's state directory beside the records (written atomically: ``state_file``), with the plan
it followed — the robot's geometry hash and the options — so that ``--resume`` continues from
it on the same robot with the same plan, and refuses in one line otherwise. A procedure that
completes removes it (docs/homing.md, "A stopped calibration keeps its samples";
docs/safety.md, "Brake test")."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

from cdprctl.core.state_file import read_dataclass, write_json

FORMAT = 1
# the file of each procedure (a kind), in the state directory
FILES = {
    "geometry": "calibration-geometry.partial.json",
    "self": "calibration-self.partial.json",
    "brake-test": "brake_test.partial.json",
    "friction": "calibration-friction.partial.json",
}
# the docs a timing fault points at: the machine's load, not the robot
REALTIME_DOCS = 'docs/control.md, "Real time" and "Late and missed periods"'


class PartialSessionError(Exception):
    """A partial session that is missing, unreadable or not of this robot and plan: one line
    naming what differs and the fix."""


@dataclasses.dataclass
class PartialSession:
    kind: str  # a key of FILES
    robot: str
    geometry_hash: str  # the robot file's (calibration.record.geometry_hash)
    options: dict[str, Any]  # what the plan followed, by name
    fault: str  # what stopped it, as said
    stopped_at: str  # where, in words ("pose 14 of 24", "cable 4 of 8")
    kept: int  # samples (or cables) kept
    data: dict[str, Any]  # the samples, the procedure's own
    time: str  # ISO 8601, UTC: when it stopped
    started: float  # s since the epoch: when the first of its samples was taken
    simulated: bool = False
    identities: list[Any] = dataclasses.field(default_factory=list)  # the drives' 0x1018


def path_of(state_dir: Path, kind: str) -> Path:
    return Path(state_dir) / FILES[kind]


def save(partial: PartialSession, state_dir: Path) -> Path:
    return write_json(path_of(state_dir, partial.kind), FORMAT, partial)


def load(state_dir: Path, kind: str) -> PartialSession:
    """The partial session of ``kind`` in ``state_dir``; :class:`PartialSessionError`."""
    path = path_of(state_dir, kind)
    partial = _read(path)
    if partial.kind != kind:
        raise PartialSessionError(f"{path}: a {partial.kind} session, not a {kind} one")
    return partial


def _read(path: Path) -> PartialSession:
    """The partial session at ``path``, of whichever kind; :class:`PartialSessionError`."""
    return read_dataclass(PartialSession, path, FORMAT, "stopped session to resume",
                          PartialSessionError)  # fmt: skip


def keep_in_data(path: Path, key: str, value: Any) -> None:
    """``value`` under ``key`` in the procedure's data of the partial session at ``path``
    (what a resume found that a later one could no longer see: a drive's reset, which the
    refused resume's own set-up clears)."""
    partial = _read(path)
    partial.data[key] = value
    write_json(path, FORMAT, partial)


def remove(state_dir: Path | None, kind: str) -> bool:
    """Remove the partial session of ``kind`` (a completed procedure); whether there was one."""
    if state_dir is None:
        return False
    path = path_of(state_dir, kind)
    existed = path.exists()
    path.unlink(missing_ok=True)
    return existed


def check_plan(partial: PartialSession, path: Path, robot: str, hash_now: str,
               options: dict[str, Any], where: dict[str, str]) -> None:  # fmt: skip
    """That ``partial`` (read from ``path``) is of ``robot`` with the geometry hash
    ``hash_now`` and ``options``; :class:`PartialSessionError` naming the first difference
    (``where``: the option or field that sets each option) otherwise."""
    fix = ("resume with the robot file and options it was started with, or start over "
           "without --resume")
    if partial.robot != robot:
        raise PartialSessionError(f"{path} is robot {partial.robot!r}'s, not {robot!r}'s: {fix}")
    if partial.geometry_hash != hash_now:
        raise PartialSessionError(
            f"{path} was measured on another geometry (hash {partial.geometry_hash}, this robot "
            f"file's {hash_now}: anchors, drums, encoders, elasticity or home differ): {fix}"
        )
    for name in sorted(set(partial.options) | set(options)):
        then, now = partial.options.get(name), options.get(name)
        if not _same(then, now):
            how = f" ({where[name]})" if name in where else ""
            raise PartialSessionError(f"{path} was planned with {name} = {then}, this run's is "
                                      f"{now}{how}: {fix}")  # fmt: skip


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return math.isclose(float(a), float(b), rel_tol=1e-12, abs_tol=0.0)
    return bool(a == b)


def check_identities(then: list[Any], now: list[Any], names: list[str], path: Path) -> None:
    """The drives are those the partial session measured with (0x1018, where both have it)."""
    for i, (a, b) in enumerate(zip(then, now, strict=False)):
        if a and b and a != b:
            raise PartialSessionError(
                f"the drive of cable {names[i]} is not the one {path} was measured with "
                f"(identity 0x1018 {b}, then {a}): a drive was exchanged: start over without "
                "--resume"
            )


def clear_latched_fault(driver: Any, log: Any, who: str) -> None:
    """Configured to resume: a drive still holding the fault that stopped the procedure (CiA
    402 latches it until a fault reset) is reset, said in a line; one that persists stops the
    procedure again, with its own line."""
    from drivers.vocabulary import Lifecycle

    driver.read(driver.clock())
    if driver.lifecycle is Lifecycle.ERROR:
        log(f"{who}: {driver.error}: still latched from the stop: fault reset")
        driver.recover()


# of the periods, missed by this process: beyond, a quiet machine does not explain them
# (docs/control.md, "Real time": 0.001-0.21 % in the daemon's runs beside CPU hogs)
BUSY_SHARE = 0.002


def timing_cause(driver_error: Exception | None, missed: int, cycles: int) -> str:
    """Why a stop may be the machine's load rather than the robot, with the measured value and
    its limit and where the docs explain it ("" when nothing points at the load): a drive's
    feedback timeout (``driver_error``), periods this process missed (``missed`` of
    ``cycles``)."""
    from drivers.errors import DriverTimeoutError

    timeout = isinstance(driver_error, DriverTimeoutError) and "heartbeat" not in str(driver_error)
    share = (f"{missed} of {cycles} periods missed ({100.0 * missed / max(cycles, 1):.2f} %; "
             f"a quiet machine misses under {100 * BUSY_SHARE:g} %: see {REALTIME_DOCS})")
    fix = "stop other work on it (or give [control] cpu a core of its own), then resume"
    if timeout and missed:
        return f"the machine was too busy: {share}: {fix}"
    if missed > BUSY_SHARE * cycles:
        return f"the machine was busy, and a late cycle can cause this fault: {share}: {fix}"
    if timeout:
        return ("a drive's feedback stopped longer than [drives] feedback_timeout with this "
                "process on time (0 periods missed): a simulated robot's process held up by "
                f"the machine's load (see {REALTIME_DOCS}), or a drive that lost its bus or "
                "power: check it, then resume")  # fmt: skip
    return ""
