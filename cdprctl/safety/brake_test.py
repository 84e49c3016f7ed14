"""The holding brakes' test (docs/safety.md, "Brake test"): every brake closed by the master
(``WinchDriver.command_brake``), the drives enabled against them, then one cable at a time a
test torque ramped up in the pay-out direction — where the cable's load already pulls, so
the brake holds both — held, and the motor's motion measured; a brake that lets its motor
turn more than ``[safety] brake_test_max_counts`` fails, and its torque comes off the moment
it does. The drives are disabled and the brakes given back to the drives at the end, whatever
happened. At the driver's period on its clock, so the same code runs on a real robot and in
lock-step with the simulated one."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

from cdprctl.core.state_file import iso_utc
from cdprctl.model.robot import RobotModel
from cdprctl.safety.brake_record import BrakeTestRecord, CableResult
from drivers.base import WinchDriver
from drivers.errors import DriverError
from drivers.vocabulary import Lifecycle, WinchStates

RAMP = 0.5  # s from zero to the test torque: no jerk on the gearbox
SETTLE = 0.1  # s at zero torque between cables
# of the test torque, the drive's own torque actual must have reached: else it did not push
# (a drive that limits its torque below, or ignores the target) and nothing was tested
APPLIED = 0.9
ENABLE_TIMEOUT = 3.0  # s for every drive to enable against its closed brake
SDO_TIMEOUT = 1.0  # s for each answer of the brake's SDO set-up (the drives' set-up's own)


class BrakeTestFailedError(Exception):
    """The test could not run to its end (a drive fault, a brake not taken); drives disabled,
    brakes given back."""


class BrakeTestStoppedError(BrakeTestFailedError):
    """Stopped midway with cables tested: ``results`` theirs (kept: ``--resume`` goes on with
    the next), ``at`` the index of the cable under test, ``cause`` what points at the
    machine's load ("": nothing does; ``partial_session.timing_cause``), ``started`` when the
    first of them was tested (s since the epoch)."""

    def __init__(self, message: str, results: list[CableResult], at: int, cause: str,
                 started: float):  # fmt: skip
        super().__init__(message)
        self.results, self.at, self.cause, self.started = results, at, cause, started


def brake_test_torques(model: RobotModel) -> tuple[np.ndarray, np.ndarray]:
    """N·m at each motor: ``brake_test_torque``, else ``brake_test_torque_factor`` × the
    torque the cable's worst-case load (its tension limit) puts on the brake, r/G · t_max;
    never above the drive's torque limit (the second array: where that capped it)."""
    cfg = model.safety
    limit = np.array([c.winch.torque_limit for c in model.cables])
    ratio = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
    wanted = (
        np.full(model.n_cables, cfg.brake_test_torque)
        if cfg.brake_test_torque is not None
        else cfg.brake_test_torque_factor * ratio * np.asarray(model.tension_max)
    )
    return np.minimum(wanted, limit), wanted > limit


class BrakeTest:
    def __init__(self, model: RobotModel, driver: WinchDriver, log: Callable[[str], None],
                 simulated: bool = False):  # fmt: skip
        """``simulated``: the drives are the simulated robot's (the record says so, and a
        real robot's start-up does not take it)."""
        self.model, self.driver, self.log = model, driver, log
        self.simulated = simulated
        m = model.n_cables
        self.torque, self.capped = brake_test_torques(model)
        cpr = np.array([c.winch.encoder_counts_per_rev for c in model.cables], float)
        self.rad_per_count = 2.0 * math.pi / cpr
        self.bound = model.safety.brake_test_max_counts * self.rad_per_count  # rad
        self.command = np.zeros(m)  # N·m, what each drive is asked
        self.targets = np.zeros(m)  # rad: position mode holds each motor where it stood
        self.csp = model.drives.holds_lengths

    def run(self, kept: list[CableResult] | None = None,
            started: float | None = None) -> BrakeTestRecord:  # fmt: skip
        """Every cable's brake tested in turn — after those of ``kept`` (a stopped test's,
        resumed: the next cable first). The record is dated ``started`` (s since the epoch:
        the first cable's test, whose age the interval counts), now when None. Stopped
        midway with cables tested: :class:`BrakeTestStoppedError` holding their results."""
        d, names = self.driver, [c.name for c in self.model.cables]
        closed: list[int] = []
        results: list[CableResult] = list(kept or [])
        started = time.time() if started is None else started
        try:
            for c in range(self.model.n_cables):
                d.command_brake(c, True, SDO_TIMEOUT)
                closed.append(c)
            self.log("brakes closed by the master (0x60FE 'set brake'); enabling the drives")
            d.activate(ENABLE_TIMEOUT)  # zero torque, the targets where the motors stand
            self.targets[:] = d.states.position
            if results:
                self.log(f"resumed: cables {', '.join(r.cable for r in results)} kept from "
                         "the stopped test")  # fmt: skip
            for c, name in enumerate(names[len(results):], start=len(results)):
                results.append(self._one(c, name))
        except (BrakeTestFailedError, DriverError) as exc:
            if not results:
                raise
            from cdprctl.calibration.partial_session import timing_cause

            raise BrakeTestStoppedError(str(exc), results, len(results),
                                        timing_cause(d.error, 0, 0), started) from None
        finally:
            self._finish(closed)
        return BrakeTestRecord(
            robot=self.model.name,
            time=iso_utc(started),
            unix_time=started,
            passed=all(r.passed for r in results),
            max_counts=self.model.safety.brake_test_max_counts,
            cables=results,
            identities=list(getattr(d, "identities", [None] * self.model.n_cables)),
            simulated=self.simulated,
        )

    def _one(self, c: int, name: str) -> CableResult:
        """Cable index ``c``'s brake under its test torque: ramped over RAMP, held for
        ``brake_test_hold``, off at once when the motion passes its bound."""
        d = self.driver
        start = d.states.position.copy()
        total = RAMP + self.model.safety.brake_test_hold
        n = max(1, round(total / d.period))
        worst, early, applied = 0.0, False, 0.0
        for i in range(n):
            self.command[c] = -self.torque[c] * min(1.0, (i + 1) * d.period / RAMP)
            states = self._cycle()
            worst = max(worst, abs(float(states.position[c] - start[c])))
            applied = max(applied, -float(states.torque[c]))  # the drive's torque actual
            if worst > self.bound[c]:
                early = True
                break
        self.command[c] = 0.0
        self._run(SETTLE)
        held = bool(worst <= self.bound[c])
        # a drive that did not apply the torque tested nothing: a fail, not a pass
        pushed = bool(early or applied >= APPLIED * self.torque[c])
        counts = round(float(worst / self.rad_per_count[c]), 2)
        bound = self.model.safety.brake_test_max_counts
        verdict = "pass" if held and pushed else "FAIL" + (
            "" if pushed else f": the drive applied only {applied:.3f} N·m")  # fmt: skip
        self.log(f"  cable {name} (index {c}): {self.torque[c]:.3f} N·m"
                 + (" (the drive's limit)" if self.capped[c] else "")
                 + f", applied {applied:.3f}, moved {counts:.1f} counts (at most {bound}): "
                 + verdict)  # fmt: skip
        return CableResult(name, held and pushed, float(self.torque[c]), round(applied, 6),
                           worst, counts, bool(self.capped[c]), early)  # fmt: skip

    def _run(self, duration: float) -> None:
        for _ in range(max(1, round(duration / self.driver.period))):
            self._cycle()

    def _cycle(self) -> WinchStates:
        d = self.driver
        states = d.read(d.clock())
        if d.lifecycle is Lifecycle.ERROR:
            raise BrakeTestFailedError(f"the drives stopped: {d.error}")
        d.write(d.clock(), self.command, targets=self.targets if self.csp else None)
        d.wait(d.period)
        return states

    def _finish(self, closed: list[int]) -> None:
        """Drives disabled (their brakes close by themselves), then each brake given back to
        its drive: best effort, each failure said."""
        d = self.driver
        self.command[:] = 0.0
        try:
            d.deactivate()
        except DriverError as exc:
            self.log(f"warning: disabling the drives: {exc}")
        for c in closed:
            try:
                d.command_brake(c, False, SDO_TIMEOUT)
            except DriverError as exc:
                self.log(f"warning: cable index {c}: giving its brake back to the drive: {exc}")

