"""A jog: a velocity command held alive by its sender (``docs/operating.md``).

``Controller.submit`` turns each jog command into a segment along its direction that ends
where the soft limits do (``motion.limits.SoftLimits.ray_end``): ruckig brakes before the
bound and stops at it, never past. The sender repeats the command; when none has arrived for
``[control] jog_deadman`` s the jog stops, jerk-limited, wherever that ends (an operator
who let go, a lost link)."""

from __future__ import annotations

import numpy as np

from cdprctl.control.commands import Command
from cdprctl.control.data import ControlData
from cdprctl.motion.trajectory import Trajectory


class Jog:
    def __init__(self, data: ControlData, trajectory: Trajectory, deadman: float):
        self.data = data
        self.trajectory = trajectory
        self.deadman = deadman  # s
        self.active = False
        self.last = 0.0  # s, loop time of the last jog command
        self._rest = [0.0] * 6  # the segment ends at rest (ruckig's target velocity)

    def command(self, t: float, cmd: Command) -> None:
        """Follow ``cmd`` (checked and planned by ``Controller.submit``)."""
        if cmd.target is None or cmd.limits is None:  # a zero velocity: stop
            self.stop()
            return
        tr = self.trajectory
        if tr.finished and float(np.max(np.abs(cmd.target - tr.position))) < 1e-9:
            return  # already at the bound: nothing to move, no state to change
        vmax, amax = cmd.limits
        self.trajectory.set_segment(cmd.target, self._rest, vmax, amax)
        self.active = True
        self.last = t
        self.data.motion = "jog"

    def stop(self) -> None:
        if self.active:
            self.trajectory.stop_here()
        self.active = False

    def update(self, t: float) -> None:
        """The deadman: no jog for ``deadman`` s → a jerk-limited stop."""
        if self.active and t - self.last > self.deadman:
            self.active = False
            if not self.trajectory.finished:
                self.trajectory.stop_here()
                self.data.events.append(
                    (t, f"jog: no jog command for {self.deadman:g} s (deadman): stopping")
                )
