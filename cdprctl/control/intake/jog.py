"""A jog: a velocity command held alive by its sender (``docs/operating.md``).

The command desk's ``submit`` (``desk.CommandDesk``) turns each jog command into a segment
along its direction that ends where the soft limits do (``motion.limits.SoftLimits.ray_end``):
ruckig brakes before the bound and stops at it, never past. The sender repeats the command;
when none has arrived for ``[control] jog_deadman`` s the jog stops, jerk-limited, wherever
that ends (an operator who let go, a lost link)."""

from __future__ import annotations

import numpy as np

from cdprctl.control.command_types import NOTHING, JogCommand, Plan
from cdprctl.control.data import ControlData
from cdprctl.control.intake.motion_source import MotionSource
from cdprctl.core.rotation import FloatArray
from cdprctl.model.robot import RobotModel
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.path_plan import FLOOR
from cdprctl.motion.trajectory import Trajectory, coordinates_rotation


class Jog(MotionSource):
    def __init__(self, model: RobotModel, data: ControlData):
        super().__init__(model, data)
        self.deadman = model.control.jog_deadman  # s
        self._bound: FloatArray | None = None  # where the last jog's limits ended it
        self.active = False
        self.last = 0.0  # s, loop time of the last jog command
        self._rest = [0.0] * 6  # the segment ends at rest (ruckig's target velocity)

    def plan(self, cmd: JogCommand, trajectory: Trajectory, limits: SoftLimits) -> Plan | None:
        """Outside the loop (``CommandDesk.submit``): the jog's segment from the
        ``trajectory``'s reference, along its velocity to where the soft ``limits`` end it
        (ruckig brakes to stop there; a zero velocity: a stop, no target). None (with an
        event) when the command is unusable."""
        d = self.data
        v = None if cmd.velocity is None else np.asarray(cmd.velocity, dtype=float)
        if v is None or v.shape != (6,) or not np.all(np.isfinite(v)) or np.any(
            np.abs(v) > trajectory.limits * (1 + 1e-9)
        ) or cmd.frame not in ("base", "platform"):  # fmt: skip
            d.events.append((d.time, "jog ignored: velocity not 6 finite numbers within the "
                             "configured limits, or frame not base/platform"))  # fmt: skip
            return None
        if not np.any(v):
            return NOTHING  # a stop
        start = trajectory.position.copy()
        if cmd.frame == "platform":
            R = coordinates_rotation(self.model.home.rotation, start[3:])
            v = np.concatenate([R @ v[:3], R @ v[3:]])
        ws = self.model.workspace
        speed, turn = float(np.linalg.norm(v[:3])), float(np.linalg.norm(v[3:]))
        reach = float(np.linalg.norm(ws.position_max - ws.position_min))
        horizon = reach / speed if speed > 0 else 2.0 * ws.max_angle / turn  # s
        end, why = limits.ray_end(start, v, horizon, step=0.02)
        vmax = np.maximum(np.abs(v), FLOOR * trajectory.limits)
        segment = Plan(target=end, limits=(vmax.tolist(), trajectory.full_acceleration))
        # one event per bound met, not one per repeated command (the end moves by a bisection
        # step as the reference approaches it)
        bound = end if why else None
        if bound is not None and (
            self._bound is None or float(np.max(np.abs(bound - self._bound))) > 2e-3
        ):
            d.events.append((d.time, f"jog: stops at {np.round(end[:3], 4).tolist()} m: {why}"))
        self._bound = bound
        return segment

    def command(self, t: float, plan: Plan, tr: Trajectory) -> bool:
        """Follow a jog's ``plan`` (its segment, from ``plan`` by ``CommandDesk.submit``) on
        the trajectory ``tr``;
        whether it set a segment to follow (False: a stop, or already at the bound)."""
        if plan.target is None or plan.limits is None:  # a zero velocity: stop
            self.stop(tr)
            return False
        if tr.finished and float(np.max(np.abs(plan.target - tr.position))) < 1e-9:
            return False  # already at the bound: nothing to move, no state to change
        vmax, amax = plan.limits
        tr.set_segment(plan.target, self._rest, vmax, amax)
        self.active = True
        self.last = t
        return True

    def stop(self, tr: Trajectory) -> None:
        """A jog under way braked to rest on ``tr``."""
        if self.active:
            tr.stop_here()
        self.active = False

    def update(self, t: float, trajectory: Trajectory) -> None:
        """The deadman: no jog for ``deadman`` s → a jerk-limited stop of ``trajectory``."""
        if self.active and t - self.last > self.deadman:
            self.active = False
            if not trajectory.finished:
                trajectory.stop_here()
                self.data.events.append(
                    (t, f"jog: no jog command for {self.deadman:g} s (deadman): stopping")
                )
