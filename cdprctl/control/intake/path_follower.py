"""Plays a checked path plan (``motion.path_plan``) in the loop: each segment handed to the
trajectory when the last one ends (or its dwell has passed), the progress written into
``ControlData`` (``path_segment``, ``path_fraction``, ``path_state``, ``path_elapsed``,
``path_time_left``: the plan's duration less the time it has played). Pause brakes onto the
path and holds; resume continues with a plan the desk's ``submit`` made from where it stands;
abort brakes and forgets the path; a fault or a stop ends it ("stopped")."""

from __future__ import annotations

import math

import numpy as np

from cdprctl.control.command_types import NOTHING, PathCommand, Plan
from cdprctl.control.data import ControlData
from cdprctl.control.intake.motion_source import MotionSource
from cdprctl.control.states import State
from cdprctl.model.robot import RobotModel
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.path_plan import PathPlan, PathRejectedError, plan_path, plan_text
from cdprctl.motion.trajectory import Trajectory
from cdprctl.motion.waypoints import PathFileError


class PathFollower(MotionSource):
    def __init__(self, model: RobotModel, data: ControlData):
        super().__init__(model, data)
        self.plan: PathPlan | None = None
        self.k = 0  # the segment under way (0-based, in ``plan``)
        self.offset = 0  # segments of the original path before ``plan`` (after a resume)
        self.paused = False
        self._dwell_until = math.nan
        self._seg_start = np.zeros(6)
        self._seg_length = 0.0
        self._ends_at = math.nan  # s: when the plan under way ends, as planned
        self._played = 0.0  # s the path had played before the plan under way (a resume)
        self._started = 0.0  # s: when the plan under way started

    # -- outside the loop (the desk's submit) ---------------------------------------------------
    def plan_path(self, cmd: PathCommand, tr: Trajectory, limits: SoftLimits) -> Plan | None:
        """Parse and check the whole path from where the reference of ``tr`` is, against the
        soft ``limits`` (motion/path_plan.py);
        None (an event naming the line and the rule) when it is refused. The loop starts it
        only in ENABLED (``ACCEPTED_IN``) with the reference still there, at rest."""
        d = self.data
        name = cmd.name or "(payload)"
        if cmd.plan is not None and cmd.plan[0].starts_at(tr.position):
            return Plan(path=cmd.plan)  # checked already (the gateway, --path) from there
        try:
            plan = plan_text(self.model, cmd.text, tr.position.copy(), self.model.control.period,
                             limits, name)  # fmt: skip
        except (PathFileError, PathRejectedError) as exc:
            d.events.append((d.time, f"path {name} rejected: {exc}"))
            return None
        return Plan(path=(plan, 0))

    def plan_resume(self, tr: Trajectory, limits: SoftLimits) -> Plan | None:
        """The rest of a paused path from where the reference of ``tr`` stands, checked
        against the soft ``limits`` again."""
        if self.plan is None or not self.paused:
            return NOTHING  # the loop says so (CommandDesk._resume)
        k, offset = self.remaining()
        plan = self.plan
        durations = [None, *plan.durations[k + 1 :]]
        try:
            here = tr.position.copy()
            rest = plan_path(self.model, plan.waypoints[k:], here, self.model.control.period,
                             limits, plan.name, durations)  # fmt: skip
        except PathRejectedError as exc:
            self.data.events.append((self.data.time, f"resume refused: {exc}"))
            return None
        return Plan(path=(rest, offset))

    # -- in the loop -------------------------------------------------------------------------------
    @property
    def holds_motion(self) -> bool:
        """True while the path runs (in a dwell too): its state stays MOVING."""
        return self.plan is not None and not self.paused

    def start(self, t: float, plan: PathPlan, offset: int, tr: Trajectory) -> None:
        """Play ``plan`` (the path's segments from ``offset`` on) on the trajectory ``tr``."""
        d = self.data
        resumed = self.paused and self.plan is not None
        self._played = d.path_elapsed if resumed else 0.0
        self._started, self._ends_at = t, t + plan.duration
        d.path_elapsed, d.path_time_left = self._played, plan.duration
        self.plan, self.offset, self.paused = plan, offset, False
        self.k = -1
        d.path_segments = offset + len(plan.segments)
        self._next(t, tr)

    def _next(self, t: float, tr: Trajectory) -> None:
        d, plan = self.data, self.plan
        assert plan is not None
        self.k += 1
        if self.k >= len(plan.segments):
            self._end(t, "done", f"path {plan.name}: done")
            return
        s = plan.segments[self.k]
        self._seg_start[:] = tr.position
        self._seg_length = math.dist(s.target, self._seg_start)  # in the 6 coordinates
        self._dwell_until = math.nan
        tr.set_segment(s.target, s.velocity, s.max_velocity, s.max_acceleration,
                                    s.minimum_duration)  # fmt: skip
        d.path_state = "running"
        d.path_segment = self.offset + self.k + 1
        d.path_fraction = 0.0

    def _end(self, t: float, state: str, why: str) -> None:
        d = self.data
        self.plan = None
        self.paused = False
        d.path_state = state
        if state == "done":
            d.path_time_left = 0.0
        d.events.append((t, why))

    def update(self, t: float, tr: Trajectory) -> None:
        """Before the supervisor looks at the trajectory ``tr``: the next segment when one
        ends."""
        d, plan = self.data, self.plan
        if plan is None or self.paused:
            return
        if d.state is not State.MOVING:  # a fault, a disable: the supervisor stops the robot
            self._end(t, "stopped", f"path stopped at segment {d.path_segment} "
                                    f"(state {d.state.value})")  # fmt: skip
            return
        d.path_elapsed = self._played + t - self._started
        d.path_time_left = max(0.0, self._ends_at - t)
        s = plan.segments[self.k]
        total = self._seg_length
        left = math.dist(s.target, tr.position)
        d.path_fraction = 1.0 if total <= 1e-12 else min(1.0, max(0.0, 1.0 - left / total))
        if not tr.finished:
            return
        if s.dwell > 0.0:
            if math.isnan(self._dwell_until):
                self._dwell_until = t + s.dwell
                d.path_state = "dwell"
            if t < self._dwell_until:
                return
        self._next(t, tr)

    def pause(self, t: float, tr: Trajectory) -> None:
        """The path braked to rest on ``tr`` and held there."""
        if self.plan is None:
            return
        self.paused = True
        tr.stop_here()
        self.data.path_state = "paused"
        self.data.events.append((t, f"path paused in segment {self.data.path_segment}"))

    def abort(self, t: float, tr: Trajectory) -> None:
        """The path braked to rest on ``tr`` and forgotten."""
        if self.plan is None and not self.paused:
            return
        tr.stop_here()
        self._end(t, "aborted", f"path aborted in segment {self.data.path_segment}")

    def remaining(self) -> tuple[int, int]:
        """(index in the plan, index in the original path) of the segment a resume starts
        with."""
        return self.k, self.offset + self.k
