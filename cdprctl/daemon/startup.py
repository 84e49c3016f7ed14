"""The daemon's start-up, in order: the links (gateway, view), the real-time settings, the
calibration record, the drives and the pose (``ControllerManager.startup``), a ``--path``
checked whole. Each refusal is one ``StartupRefusedError`` with its line and exit code; the caller
closes what was opened."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from cdprctl import realtime as rt
from cdprctl.daemon.report import identity_lines
from cdprctl.daemon.scripts import PathScript

if TYPE_CHECKING:
    from cdprctl.daemon.service import Daemon

NOT_CALIBRATED = 4  # exit code: no valid calibration record (systemd: no restart)


class StartupRefusedError(Exception):
    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.message, self.code = message, code


def start_up(dm: Daemon, path: tuple[str, str, str] | None) -> PathScript | None:
    """Everything before ``ready``; returns the ``--path`` script (planned), if any."""
    from cdprctl.calibration.record import CalibrationError
    from cdprctl.calibration.startup import how_to_calibrate, load_record

    m = dm.model
    failure = dm.links.start()
    if failure:
        raise StartupRefusedError(f"cdprctl run: {failure}", 1)
    for link in dm.links.links:  # what each link is, once it runs
        for text, err in link.announcement():
            dm._print(text, err=err)
    # real-time settings next (the gateway, started before, keeps its own CPU affinity);
    # locking memory and freezing the collector take a while, and once the drives are started
    # their heartbeats are watched
    if dm.realtime:
        rc = m.control
        for w in rt.apply_realtime(rc.sched_priority, rc.cpu, rc.lock_memory, rc.freeze_gc):
            dm._print(f"warning: {w}", err=True)

    def refused(why: str) -> StartupRefusedError:  # no enable without a valid calibration
        return StartupRefusedError(f"cdprctl run: refusing to enable the drives: {why}; "
                              f"{how_to_calibrate(m, dm.state_dir)}", NOT_CALIBRATED)  # fmt: skip

    if dm.assume_home:
        dm._print("encoders: taken as zero at the home pose ("
                  + ("the simulated robot starts there" if dm.sim else
                     "[drives] assume_home_at_start = true") + ")")  # fmt: skip
    else:
        try:
            dm.record = load_record(m, dm.state_dir)
        except CalibrationError as exc:
            raise refused(str(exc)) from None
        dm._print(f"calibration: {dm.record.method} of {dm.record.time} ({dm.state_dir})")
    dm._print("start-up: loading the compiled kernels (the first run on a machine compiles "
              "them: about a minute), configuring the drives, estimating the pose")  # fmt: skip
    try:
        dm.manager.startup(calibration=None if dm.assume_home else _calibration(dm))
    except CalibrationError as exc:
        raise refused(str(exc)) from None
    except Exception as exc:  # start-up failures are reported, never a traceback
        hint = "" if dm.assume_home else f" ({how_to_calibrate(m, dm.state_dir)})"
        raise StartupRefusedError(f"cdprctl run: start-up failed: {exc}{hint}", 1) from None
    for w in dm.driver.warnings:
        dm._print(f"warning: {w}", err=True)
    lines, drives = identity_lines(m, dm.driver)
    for line in lines:
        dm._print(line)
    if drives:
        dm.links.event(dm.data.time, drives, "drives")
    return None if path is None else _plan_path(dm, *path)


def _calibration(dm: Daemon) -> Any:
    """The record's offsets, once the configured drives match it (``Manager.startup``)."""

    def offsets_of(driver: Any) -> tuple[np.ndarray, np.ndarray]:
        from cdprctl.calibration.startup import check_drives, offsets

        check_drives(dm.model, dm.record, driver)
        return offsets(dm.record)

    return offsets_of


def _plan_path(dm: Daemon, name: str, text: str, units: str) -> PathScript:
    """The whole path from the pose start-up found, checked before any motion (``units``: a
    CSV's lengths without a row of units)."""
    from cdprctl.motion.limits import SoftLimits
    from cdprctl.motion.path_file import PathFileError
    from cdprctl.motion.path_plan import PathRejectedError, plan_text, units_hint

    try:
        plan = plan_text(dm.model, text, dm.data.reference.copy(), dm.model.control.period,
                         SoftLimits(dm.model), name, units)  # fmt: skip
    except (PathFileError, PathRejectedError) as exc:
        why = f"{exc}{units_hint(text, units, str(exc))}"
        raise StartupRefusedError(f"cdprctl run: path {name} rejected: {why}", 2) from None
    dm._print(f"path {name}: {plan.summary()}")
    return PathScript(name, text, plan)
