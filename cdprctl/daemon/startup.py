"""The daemon's start-up, in order: the links (gateway, view), the calibration record, the
compiled kernels, memory locked, the drives and the pose (``ControllerManager.startup``), a
``--path`` checked whole — all at the normal scheduler (SCHED_FIFO only for the loop). Each
refusal is one ``StartupRefusedError`` with its line and exit code; the caller closes what was
opened."""

from __future__ import annotations

import contextlib
import signal
import sys
import time
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from cdprctl.core import realtime as rt
from cdprctl.daemon.report import identity_lines
from cdprctl.daemon.scripts import PathScript

if TYPE_CHECKING:
    from pathlib import Path

    from cdprctl.calibration.calibration_record import CalibrationRecord
    from cdprctl.control.data import ControlData
    from cdprctl.control.lifecycle.manager import ControllerManager
    from cdprctl.daemon.links import Links
    from cdprctl.model import RobotModel
    from sim_backend.process import SimulatedRobotProcess

NOT_CALIBRATED = 4  # exit code: no valid calibration record or brake test (systemd: no restart)


class StartupRefusedError(Exception):
    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.message, self.code = message, code


class StartupInterrupted(KeyboardInterrupt):
    """SIGTERM or SIGINT before ``ready``: nothing was enabled, so the stop is the start-up's
    end — what was opened closed, one line, exit 0 (as a stop after ``ready``)."""

    code = 0

    def __init__(self, signame: str):
        super().__init__(signame)
        self.message = (f"cdprctl run: stopped by {signame} during the start-up; the drives "
                        "were not enabled")  # fmt: skip


_received: list[str] = []  # the stop signals received during the start-up, by name


def interrupt_the_start_up() -> dict[signal.Signals, Any]:
    """SIGTERM and SIGINT raise ``StartupInterrupted`` until the loop installs its controlled
    stop (``Daemon.run``): without it, SIGTERM killed the start-up mid-way (its helper
    processes left running) and Ctrl-C printed a traceback from inside a kernel's compile.
    The signal is also kept: raised inside a library's callback (llvmlite's object cache,
    during a compile) the exception was swallowed and the start-up went on to ``ready``, so
    ``stop_if_interrupted`` raises it again at the start-up's steps. Returns the handlers it
    replaced."""
    _received.clear()
    if not getattr(sys.unraisablehook, "keeps_stop_signals", False):
        previous_hook = sys.unraisablehook

        def hook(u: Any) -> None:
            """A stop raised inside a library's callback is swallowed there (kept in
            ``_received``); without this Python printed it as "Exception ignored ...
            Traceback" (a Ctrl-C during a first run's compile, 1 start-up in 2)."""
            if not isinstance(u.exc_value, StartupInterrupted):
                previous_hook(u)

        hook.keeps_stop_signals = True  # type: ignore[attr-defined]
        sys.unraisablehook = hook

    def raise_it(signum: int, _frame: object) -> None:
        _received.append(signal.Signals(signum).name)
        raise StartupInterrupted(_received[-1])

    return {s: signal.signal(s, raise_it) for s in (signal.SIGTERM, signal.SIGINT)}


def stop_if_interrupted() -> None:
    """Raise ``StartupInterrupted`` if a stop signal came during the start-up."""
    if _received:
        raise StartupInterrupted(_received[0])


def forget_stop_signals() -> None:
    """At the start-up's end, whichever: a later run in this process starts clean."""
    _received.clear()


class StartingDaemon(Protocol):
    """What the start-up reads and sets of the daemon (``service.Daemon``), given to it
    rather than the daemon's class imported (the daemon calls the start-up)."""

    model: RobotModel
    bus_hint: str  # the bus options given, as options: the refusals' commands repeat them
    simulated_robot: bool
    state_dir: Path
    assume_home: bool
    realtime: bool
    record: Any  # the calibration record the start-up loads
    brake_record: Any  # the brake test a real robot's start-up took
    sim: SimulatedRobotProcess | None
    driver: Any
    manager: ControllerManager
    data: ControlData
    links: Links

    def say(self, text: str, err: bool = False) -> None: ...


def start_up(dm: StartingDaemon, path: tuple[str, str, str] | None) -> PathScript | None:
    """Everything before ``ready``; returns the ``--path`` script (planned), if any."""
    from cdprctl.calibration.calibration_record import CalibrationError
    from cdprctl.calibration.startup_checks import how_to_calibrate, load_record

    m = dm.model
    failure = dm.links.start()
    if failure:
        raise StartupRefusedError(f"cdprctl run: {failure}", 1)
    for link in dm.links.links:  # what each link is, once it runs
        for text, err in link.announcement():
            dm.say(text, err=err)

    def refused(why: str) -> StartupRefusedError:  # no enable without a valid calibration
        how = how_to_calibrate(m, dm.state_dir, dm.bus_hint)
        return StartupRefusedError(f"cdprctl run: refusing to enable the drives: {why}; {how}",
                                   NOT_CALIBRATED)  # fmt: skip

    if dm.assume_home:
        dm.say("encoders: taken as zero at the home pose ("
                  + ("the simulated robot starts there" if dm.sim else
                     "[drives] assume_home_at_start = true") + ")")  # fmt: skip
        if not dm.sim:  # no zeros needed, but a friction calibration on record still applies
            with contextlib.suppress(CalibrationError):
                _friction(dm, load_record(m, dm.state_dir, dm.simulated_robot))
    else:
        try:
            dm.record = load_record(m, dm.state_dir, dm.simulated_robot)
        except CalibrationError as exc:
            raise refused(str(exc)) from None
        dm.say(f"calibration: {dm.record.method} of {dm.record.time} ({dm.state_dir})")
        _friction(dm, dm.record)
        _brakes_tested(dm)
    dm.say("start-up: loading the compiled kernels (the first run on a machine compiles "
              "them: about a minute), configuring the drives, estimating the pose")  # fmt: skip
    stop_if_interrupted()
    dm.manager.warm_up()
    stop_if_interrupted()
    # SCHED_FIFO comes last, right before the loop (Daemon.run). The collector is frozen
    # without --no-realtime's privileges too: after a first run's compile a full collection
    # on a slow CPU held the loop 0.6 s (the HIL demo under User-Mode Linux: feedback fault)
    for w in rt.lock_memory_and_freeze_gc(dm.realtime and m.control.lock_memory,
                                          m.control.freeze_gc):  # fmt: skip
        dm.say(f"warning: {w}", err=True)
    try:
        dm.manager.startup(calibration=None if dm.assume_home else _calibration(dm))
    except CalibrationError as exc:
        raise refused(str(exc)) from None
    except Exception as exc:  # start-up failures are reported, never a traceback
        hint = "" if dm.assume_home else f" ({how_to_calibrate(m, dm.state_dir, dm.bus_hint)})"
        raise StartupRefusedError(f"cdprctl run: start-up failed: {exc}{hint}", 1) from None
    if dm.brake_record is not None:  # the brakes tested are these drives'
        from cdprctl.safety.brake_record import BrakeTestError, check_drives, how_to_test

        try:
            check_drives(dm.brake_record, list(getattr(dm.driver, "identities", [])),
                         [c.name for c in m.cables])  # fmt: skip
        except BrakeTestError as exc:
            why = f"{exc}; {how_to_test(m, dm.state_dir, dm.bus_hint)}"
            raise StartupRefusedError(
                f"cdprctl run: refusing to enable the drives: {why}", NOT_CALIBRATED
            ) from None
    _load_cells_zeroed(dm)
    for w in dm.driver.warnings:
        dm.say(f"warning: {w}", err=True)
    lines, drives = identity_lines(m, dm.driver)
    for line in lines:
        dm.say(line)
    if drives:
        dm.links.event(dm.data.time, drives, "drives")
    return None if path is None else _plan_path(dm, *path)


def _friction(dm: StartingDaemon, record: CalibrationRecord) -> None:
    """``record``'s friction calibration, if any, in place of the robot file's winch terms
    (the torque law, the tension estimate, the observer: the controller's ``WinchTorques``)."""
    from cdprctl.calibration.friction_record import friction_line, friction_terms

    terms = friction_terms(record)
    if terms is not None:
        dm.manager.controller.winches.apply_friction(*terms)
    dm.say(friction_line(record))


def _load_cells_zeroed(dm: StartingDaemon) -> None:
    """The load cells' tare (`cdprctl load-cells zero`) applied where there is one; without
    it the file's offsets, said (cdprctl/calibration/load_cells.py)."""
    from cdprctl.calibration.load_cells import LoadCellError, apply, load

    if not dm.model.sensors.load_cells:
        return
    try:
        record = load(dm.state_dir)
        if record.simulated and not dm.simulated_robot:
            raise LoadCellError(f"{record.time}'s tare was a simulated robot's")
        apply(record, dm.model, dm.driver)
    except LoadCellError as exc:
        dm.say(f"warning: load cells: {exc}: the robot file's offsets (`cdprctl load-cells "
                  "zero` tares them)", err=True)  # fmt: skip
        return
    dm.say(f"load cells: zeroed {record.time} ({dm.state_dir})")


def _brakes_tested(dm: StartingDaemon) -> None:
    """A real robot is enabled only with a passed brake test younger than ``[safety]
    brake_test_interval`` on record (not with ``--sim`` or ``assume_home_at_start``: the
    simulated robot)."""
    from cdprctl.safety.brake_record import BrakeTestError, check_due, due_time, how_to_test

    try:
        last = check_due(dm.model, dm.state_dir, time.time(), dm.simulated_robot)
    except BrakeTestError as exc:
        why = f"{exc}; {how_to_test(dm.model, dm.state_dir, dm.bus_hint)}"
        raise StartupRefusedError(
            f"cdprctl run: refusing to enable the drives: {why}", NOT_CALIBRATED
        ) from None
    dm.brake_record = last
    dm.say(f"brakes: tested {last.time}, the next test due {due_time(last, dm.model)}")


def _calibration(dm: StartingDaemon) -> Any:
    """The record's offsets, once the configured drives match it (``Manager.startup``)."""

    def offsets_of(driver: Any) -> tuple[np.ndarray, np.ndarray]:
        from cdprctl.calibration.startup_checks import check_drives, offsets

        check_drives(dm.model, dm.record, driver)
        return offsets(dm.record)

    return offsets_of


def _plan_path(dm: StartingDaemon, name: str, text: str, units: str) -> PathScript:
    """The script of the path: planned whole from the pose start-up found and checked before
    the drives are enabled (``units``: a CSV's lengths without a row of units) — by the I/O
    thread once the loop runs: planned here, a long path (100 segments: 3 s) left the started
    drives unserved and they were lost ("no heartbeat for 0.510 s")."""
    from cdprctl.motion.limits import SoftLimits
    from cdprctl.motion.path_plan import PathRejectedError, plan_text, units_hint
    from cdprctl.motion.waypoints import PathFileError

    def planner(start: np.ndarray) -> tuple[Any, str]:
        """(the plan, "") or (None, why it was rejected)."""
        try:
            plan = plan_text(dm.model, text, start, dm.model.control.period,
                             SoftLimits(dm.model), name, units)  # fmt: skip
        except (PathFileError, PathRejectedError) as exc:
            return None, f"{exc}{units_hint(text, units, str(exc))}"
        dm.say(f"path {name}: {plan.summary()}")
        return plan, ""

    return PathScript(name, text, planner)
