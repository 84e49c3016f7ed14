"""Jerk-limited 6-DOF trajectories with ruckig.

The 6 coordinates are the position of ``P`` (m, base frame) and the rotation vector ``φ`` of
the orientation relative to the home orientation (``R = exp([φ]×) R_home``, rad, base frame);
for the small tilts of a CDPR (``workspace.max_angle``) ``φ̇`` is taken as the angular velocity.
ruckig ignores position limits in its community edition: targets are clamped to the workspace
box and the largest angle here, before ruckig sees them. Targets may change mid-motion: the
next update starts from the current state. The call never raises.

A segment (``set_segment``, a path's or a jog's) may end moving (a nonzero target velocity:
the path passes through its waypoint) and have its own per-coordinate limits, each no larger
than the configured ones, and a minimum duration (a timed waypoint). Every profile ruckig
returns keeps its velocity, acceleration and jerk limits; a segment starts from the state the
last one ended in (position, velocity, acceleration continuous), so the jerk limits hold
across the switch as well.
"""

from __future__ import annotations

import numpy as np
from ruckig import (
    ControlInterface,
    InputParameter,
    OutputParameter,
    Result,
    Ruckig,
    RuckigError,
    Synchronization,
)

from cdprctl.core.rotation import FloatArray, exp_so3, log_so3, matrix_to_rpy
from cdprctl.model.control import ControlConfig
from cdprctl.model.robot import RobotModel

# Phase synchronisation: a straight line in the 6-D pose space, what a point-to-point move of
# a CDPR should be; ruckig (0.19) raises RuckigError on some inputs ("error in step 1"), then
# time synchronisation, then none, are tried.
_SYNC_ORDER = (Synchronization.Phase, Synchronization.Time, Synchronization.No)
# the binding's enum members, looked up once: each lookup and each assignment of an enum to an
# input parameter took a block (the parameters are set only when they change)
_PHASE, _POSITION, _VELOCITY = (
    Synchronization.Phase,
    ControlInterface.Position,
    ControlInterface.Velocity,
)
_WORKING, _FINISHED, _ERROR = Result.Working, Result.Finished, Result.Error


def pose_coordinates(model: RobotModel, position: FloatArray, rotation: FloatArray) -> FloatArray:
    """The trajectory's 6 coordinates of a pose: ``position`` (m) and the rotation vector
    (rad) of ``rotation`` from the home orientation."""
    return np.concatenate([position, log_so3(rotation @ model.home.rotation.T)])


def coordinates_rotation(home: FloatArray, phi: FloatArray) -> FloatArray:
    """The orientation (platform → base) of the rotation vector ``phi`` (rad) from the home
    orientation ``home``: ``R = exp([φ]×) R_home``."""
    return exp_so3(np.asarray(phi, dtype=float)) @ home


def coordinates_pose(model: RobotModel, x: FloatArray) -> FloatArray:
    """x, y, z, roll, pitch, yaw (m, rad) of the trajectory coordinates ``x``."""
    R = coordinates_rotation(model.home.rotation, x[3:])
    return np.concatenate([x[:3], matrix_to_rpy(R)])


def velocity_limits(c: ControlConfig) -> FloatArray:
    """The configured limits per coordinate: m/s for the position, rad/s for the rotation."""
    return np.array([c.max_velocity] * 3 + [c.max_angular_velocity] * 3)


def acceleration_limits(c: ControlConfig) -> FloatArray:
    """The configured limits per coordinate: m/s², rad/s²."""
    return np.array([c.max_acceleration] * 3 + [c.max_angular_acceleration] * 3)


class Trajectory:
    def __init__(self, model: RobotModel, period: float):
        c = model.control
        self.model = model
        self.otg = Ruckig(6, period)
        self._dt = period  # s, ruckig's step (read from Python: the binding's costs ~µs)
        self.inp = InputParameter(6)
        self.out = OutputParameter(6)
        self.limits = velocity_limits(c)
        self.inp.max_velocity = self.limits.tolist()
        self.acc_limits = acceleration_limits(c)
        self.inp.max_acceleration = self.acc_limits.tolist()
        self.inp.max_jerk = [c.max_jerk] * 3 + [c.max_angular_jerk] * 3
        self.position = np.zeros(6)  # desired [p, φ]
        self.velocity = np.zeros(6)
        self.acceleration = np.zeros(6)
        self.target = np.zeros(6)
        self.finished = True
        self.result = Result.Finished
        self._velocity_mode = False  # braking: ruckig's velocity interface to zero velocity
        self._zero6 = [0.0] * 6
        # the configured accelerations as ruckig takes them (a stop brakes with all there is)
        self.full_acceleration = self.acc_limits.tolist()
        self._target_velocity = self._zero6  # ruckig's target velocity (a list: the binding's)
        # ruckig's input holds the last step's output as the current state (pass_to_input, in
        # C++: no list per cycle); False when the state was set from here (reset, an error)
        self._fed = False
        self.inp.synchronization = _PHASE
        self._interface = _POSITION  # the control interface the input is set to
        self.inp.control_interface = _POSITION

    def coordinates(self, position: FloatArray, rotation: FloatArray) -> FloatArray:
        return pose_coordinates(self.model, position, rotation)

    def reset(self, x: FloatArray) -> None:
        """Hold still at ``x`` (no motion, no jump)."""
        self._target_velocity = self._zero6
        self.inp.minimum_duration = None
        self.position[:] = x
        self.velocity[:] = 0.0
        self.acceleration[:] = 0.0
        self.target[:] = x
        self.finished = True
        self._velocity_mode = False
        self._fed = False

    def clamp(self, x: FloatArray) -> tuple[FloatArray, bool]:
        """``x`` inside the workspace box and the largest angle; True when it was changed."""
        ws = self.model.workspace
        y = np.array(x, dtype=float)
        y[:3] = np.clip(y[:3], ws.position_min, ws.position_max)
        angle = float(np.linalg.norm(y[3:]))
        if angle > ws.max_angle:
            y[3:] *= ws.max_angle / angle
        return y, bool(np.any(np.abs(y - x) > 1e-12))

    def set_target(self, x: FloatArray, speed_scale: float = 1.0, accel_scale: float = 1.0) -> bool:
        """New target (clamped); ``speed_scale`` and ``accel_scale`` in (0, 1] scale the
        configured velocity and acceleration limits."""
        y, _ = self.clamp(x)
        self.target[:] = y
        self.inp.max_velocity = (self.limits * min(1.0, max(1e-3, speed_scale))).tolist()
        self.inp.max_acceleration = (self.acc_limits * min(1.0, max(1e-3, accel_scale))).tolist()
        self._target_velocity = self._zero6
        self.inp.minimum_duration = None
        self._aim()
        self.finished = False
        self._velocity_mode = False
        return True

    def _aim(self) -> None:
        """ruckig's input towards ``target`` at ``_target_velocity``, by its position
        interface (set when a target or segment is given: not a list per cycle)."""
        inp = self.inp
        self._interface = inp.control_interface = _POSITION
        inp.target_position = self.target.tolist()
        inp.target_velocity = self._target_velocity
        inp.target_acceleration = self._zero6

    def set_segment(
        self,
        x: FloatArray,
        velocity: list[float],
        max_velocity: list[float],
        max_acceleration: list[float],
        minimum_duration: float | None = None,
    ) -> None:
        """A segment to ``x`` (clamped), reached at ``velocity``, with these per-coordinate
        limits (lists built outside the loop, each within the configured limits) and at least
        ``minimum_duration`` s long."""
        y, _ = self.clamp(x)
        self.target[:] = y
        self._target_velocity = velocity
        self.inp.max_velocity = max_velocity
        self.inp.max_acceleration = max_acceleration
        self.inp.minimum_duration = minimum_duration
        self._aim()
        self.finished = False
        self._velocity_mode = False

    def stop_here(self) -> None:
        """Decelerate to rest (jerk-limited) wherever that ends."""
        self.inp.current_position = self.position.tolist()
        self.inp.current_velocity = self.velocity.tolist()
        self.inp.current_acceleration = self.acceleration.tolist()
        self._fed = False  # the next step starts from these arrays, not the last output
        self._interface = self.inp.control_interface = _VELOCITY
        self.inp.max_acceleration = self.full_acceleration
        self.inp.target_velocity = self._zero6
        self.inp.target_acceleration = self._zero6
        self.inp.minimum_duration = None
        self._target_velocity = self._zero6
        self.finished = False
        self._velocity_mode = True

    def update(self, dt: float = 0.0) -> None:
        """One step of ``dt`` s (the period when 0): after a late or missed period the reference
        moves on by the time that passed, not by one period."""
        if self.finished:
            return
        if dt > 0.0 and abs(dt - self._dt) > 1e-9:
            self.otg.delta_time = self._dt = dt
        inp, out = self.inp, self.out
        if self._fed:  # the last step's output, in C++
            out.pass_to_input(inp)
        else:
            inp.current_position = self.position.tolist()
            inp.current_velocity = self.velocity.tolist()
            inp.current_acceleration = self.acceleration.tolist()
        if not self._velocity_mode and self._interface is not _POSITION:
            self._aim()
        res = self._step()
        self.result = res
        if res is _WORKING or res is _FINISHED:
            # one list per read (the binding's, given back at once), copied by index: a
            # slice assignment built an array from it
            _store(self.position, out.new_position)
            _store(self.velocity, out.new_velocity)
            _store(self.acceleration, out.new_acceleration)
            self._fed = True
            if res is _FINISHED:
                self.finished = True
                self._velocity_mode = False
        else:  # an error of ruckig's input: hold where we are
            self.velocity[:] = 0.0
            self.acceleration[:] = 0.0
            self.finished = True
            self._velocity_mode = False
            self._fed = False

    def _step(self) -> Result:
        """One ruckig step: phase synchronisation, else the fallbacks of ``_SYNC_ORDER``."""
        inp, otg, out = self.inp, self.otg, self.out
        try:
            res = otg.update(inp, out)
        except RuckigError:
            res = _ERROR
        if res is _WORKING or res is _FINISHED:
            return res
        for sync in _SYNC_ORDER[1:]:
            inp.synchronization = sync
            try:
                res = otg.update(inp, out)
            except RuckigError:
                res = _ERROR
            if res is _WORKING or res is _FINISHED:
                break
        inp.synchronization = _PHASE
        return res


def _store(a: FloatArray, v: list[float]) -> None:
    """``a[:6]`` ← ``v`` element by element (no array built from the list)."""
    a[0] = v[0]
    a[1] = v[1]
    a[2] = v[2]
    a[3] = v[3]
    a[4] = v[4]
    a[5] = v[5]
