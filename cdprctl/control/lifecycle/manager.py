"""The controller manager: it owns the drives' I/O and the loop (ros2_control's controller
manager is the pattern). Per cycle: ``driver.read`` → ``Controller.update`` → ``driver.write``,
each phase timed into ``ControlData.phase_us``; a cycle that fails anywhere ends in the
controlled stop, never in an exception out of the loop."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from cdprctl.control.command_types import Command
from cdprctl.control.cycle.controller import Controller
from cdprctl.control.data import ControlData
from cdprctl.control.intake.desk import Verdict
from cdprctl.control.lifecycle.drive_view import DriveView
from cdprctl.control.lifecycle.initialise import initialise
from cdprctl.control.lifecycle.loop import LoopStats, run_loop
from cdprctl.control.lifecycle.warm_up import warm_up
from cdprctl.model.robot import RobotModel
from cdprctl.tda import TDAOptions
from drivers.base import WinchDriver


class ControllerManager:
    def __init__(self, model: RobotModel, driver: WinchDriver, tda: TDAOptions | None = None):
        self.model = model
        self.driver = driver
        self.period = model.control.period
        self.controller = Controller(model, DriveView(driver), tda)
        self.data: ControlData = self.controller.data
        self._clock = time.perf_counter  # s as a float: no int allocated per cycle
        self._warm = False

    def warm_up(self) -> None:
        """Every kernel of the cycle compiled or loaded (``warm_up.py``); once."""
        if not self._warm:
            warm_up(self.controller)
            self._warm = True

    def startup(
        self,
        timeout: float = 5.0,
        calibration: Callable[[WinchDriver], tuple[np.ndarray, np.ndarray] | None] | None = None,
    ) -> None:
        """Compile every kernel, configure the drives, read them, estimate and check the pose
        → READY. ``calibration(driver)``, with the drives configured: the encoders' offsets
        (``theta_zero`` rad, ``drum_scale``; None: zero at home), or it raises. Raises on
        failure."""
        self.warm_up()  # before the drives start (cdprctl/control/lifecycle/warm_up.py)
        d = self.driver
        d.configure(timeout)
        found = calibration(d) if calibration is not None else None
        if found is not None:
            self.controller.estimator.apply_calibration(*found)
        now = d.clock()
        initialise(self.controller, now, d.read(now))

    def submit(self, cmd: Command) -> Verdict:
        return self.controller.desk.submit(cmd)

    def step(self, t: float) -> None:
        """One cycle at time ``t`` (s). Never raises."""
        clock, ph = self._clock, self.data.phase_us
        try:
            t0 = clock()
            st = self.driver.read(t)
            ph[0] = (clock() - t0) * 1e6
            self.controller.update(t, st)
            t6 = clock()
            self.driver.write(t, self.data.torques, targets=self.data.motor_target)
            ph[6] = (clock() - t6) * 1e6
        except Exception as exc:
            self.controller.internal_error(t, exc)

    def run(
        self,
        should_stop: Callable[[], bool],
        stats: LoopStats,
        after: Callable[[], None] | None = None,
    ) -> LoopStats:
        """The fixed-rate loop (``loop.run_loop``) until ``should_stop()``."""
        return run_loop(
            self.period,
            self.step,
            should_stop,
            self.model.control.sleep_margin,
            stats=stats,
            phases=self._phases,
            after=after,
        )

    def _phases(self) -> np.ndarray:
        return self.data.phase_us
