"""One control cycle, composed of parts with one job each (``docs/architecture.md``).

``Controller.update(t, feedback)``: commands → estimate (FK) → supervise → trajectory (ruckig)
→ pose control (PID + feedforward of gravity, platform inertia and the known external wrench)
→ TDA (the configured method; the Picard et al. 2020 Fig. 3 scheme) → winch torques
(``(r/G) t`` + friction and rotor-inertia feedforward, limits). The drives' I/O — read before,
write after — is the manager's (``manager.py``); the controller only asks the drives to change
their lifecycle (``DrivePort``). Every output lands in ``data`` (``ControlData``). Commands
arrive through a bounded mailbox, validated on the way in (``submit``, outside the loop);
their acceptance per state is the table of ``commands.py``; the states and faults are the
supervisor's (``supervisor.py``).
"""

from __future__ import annotations

import collections
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from cdprctl.control.cable_space import CableSpace
from cdprctl.control.commands import Command, CommandKind, accepted
from cdprctl.control.data import ControlData
from cdprctl.control.distribution import Distribution
from cdprctl.control.estimator import Estimator
from cdprctl.control.grippers import GripperControl
from cdprctl.control.jog import Jog
from cdprctl.control.observer import WrenchObserver
from cdprctl.control.path_follower import PathFollower
from cdprctl.control.reference_pose import ReferencePose, WorkingPose
from cdprctl.control.states import ACTIVE_STATES, HEALTHY_STATES, FaultKind, State
from cdprctl.control.supervisor import DrivePort, Supervisor
from cdprctl.control.torques import WinchTorques
from cdprctl.control.wrench import PoseController
from cdprctl.forward_kinematics import FKStatus
from cdprctl.gripper import GripperSet
from cdprctl.model.robot import RobotModel
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.trajectory import Trajectory
from cdprctl.rotation import FloatArray, rpy_to_matrix
from cdprctl.tda import TDAOptions, tda_options_of
from drivers.base import Lifecycle, WinchStates

# the states in which the external wrench is observed (the drives apply what is computed)
OBSERVED_STATES = frozenset({State.ENABLED, State.MOVING, State.STOPPING})


class Controller:
    # The feed-forward load is jerk-limited and changes slowly: the stretch tensions are
    # refreshed every 8 ms (4 cycles at 500 Hz), which halves the estimate phase's cost.
    STRETCH_PERIOD = 0.008  # s

    def __init__(self, model: RobotModel, drives: DrivePort, tda: TDAOptions | None = None):
        c = model.control
        self.model = model
        self.drives = drives
        self.period = c.period
        gs = GripperSet(model)
        self.data = d = ControlData(model.n_cables, gs.n)
        self.estimator = e = Estimator(model)
        self.trajectory = tr = Trajectory(model, self.period)
        # the pose the feed-forward, the distribution and the jaws' loads are computed at:
        # the estimate, or in position mode the reference (reference_pose.py says why)
        self.reference = ReferencePose(model, tr, e._law)
        self.at: WorkingPose = self.reference if model.drives.holds_lengths else e
        self.pose = PoseController(model, d, tr, self.at)
        self.winches = WinchTorques(model)
        self.distribution = Distribution(model, d, self.at, gs, tda or tda_options_of(model))
        self.ext_wrench = np.array(c.external_wrench, dtype=float)  # N, N·m, known
        d.ext_total[:] = self.ext_wrench
        self.observer = WrenchObserver(model, d, e, self.winches)
        self.cable_space = CableSpace(model, d, self.reference, e, self.winches)
        self.grippers = GripperControl(model, d, gs, e, self.at, self.winches,
                                       self.distribution, self.ext_wrench, tr)  # fmt: skip
        # position mode: the cables' internal tension error is supervised, per cable (N)
        tension_limits = (
            c.max_tension_disagreement * (model.tension_max - model.tension_min)
            if model.drives.holds_lengths
            else None
        )
        # position mode: a drive sitting at its torque limit is a load beyond the cables
        torque_limits = self.winches.limit if model.drives.holds_lengths else None
        self.supervisor = Supervisor(c, d, drives, tr.stop_here, tension_limits, torque_limits)
        self.mailbox: collections.deque[Command] = collections.deque(maxlen=64)
        # targets set by commands (submit, outside the loop) keep the soft limits
        self.limits = SoftLimits(model, self.ext_wrench)
        self.jog = Jog(model, d, tr, self.limits)
        self.path = PathFollower(model, d, tr, self.limits)
        # Tensions used for the estimator's stretch correction: the feed-forward ones (gravity,
        # the known external wrench and the trajectory's inertial load, distributed like the
        # commanded ones) at the estimated pose. The commanded tensions, PD feedback included,
        # would close an algebraic loop (tension → stretch → pose estimate → PD → tension) of
        # gain ~1 on the window-cleaning robot: the estimate diverged by 9 mm within 0.13 s of
        # enabling; static tensions alone leave out the inertial load, and the ill-conditioned
        # y direction turned its 0.2 mm of stretch into 6 mm of estimate (lock-step, measured).
        self._ff_wrench = np.zeros(6)
        self._last_stretch = np.full(model.n_cables, np.inf)
        self._stretch_every = max(1, round(self.STRETCH_PERIOD / self.period))
        self._clock_ns = time.perf_counter_ns
        self._last_t = -math.inf  # s, the last cycle's time
        # s: position mode, the most the reference moves on across a stall of the loop
        self._extrapolation = model.drives.target_extrapolation
        self._handlers: dict[CommandKind, Callable[[float, Command], None]] = {
            CommandKind.ENABLE: self._enable,
            CommandKind.DISABLE: self._disable,
            CommandKind.STOP: self._stop,
            CommandKind.RESET: self._reset,
            CommandKind.MOVE: self._move,
            CommandKind.SET_TDA: self._set_tda,
            CommandKind.GRIPPER: self.grippers.command,
            CommandKind.JOG: self._jog,
            CommandKind.PATH: self._path,
            CommandKind.PAUSE: self._pause,
            CommandKind.RESUME: self._resume,
            CommandKind.ABORT: self._abort,
        }
        d.gains = {
            "force_feedback": self.cable_space.iff,
            "disturbance_bandwidth": self.cable_space.disturbance_bandwidth,
            "pose_bandwidth": self.pose.bandwidth.tolist(),
        }
        # what outside readers see, bound once
        d.position, d.rotation = e.position, e.rotation
        d.velocity, d.omega = e.velocity, e.omega
        d.reference, d.target = tr.position, tr.target
        d.motor_position = drives.states.position

    # -- outside the loop ------------------------------------------------------------------------
    def initialise(self, now: float, st: WinchStates) -> None:
        """From the drives' first feedback: the pose from the home pose as a start, checked
        holdable (a TDA under gravity) → READY. Raises on failure."""
        d, e, dist = self.data, self.estimator, self.distribution
        e.reset(self.model.home.position, self.model.home.rotation)
        # The stretch depends on the tensions, which depend on the pose: a fixed point,
        # from the minimum tensions (soft cables, e.g. the Sensors 2019 springs, need a few
        # iterations; steel ones one or two).
        d.stretch_tensions[:] = self.model.tension_min
        for _ in range(100):
            fk = e.update(now, st.position, d.stretch_tensions)
            if fk.status in (FKStatus.DEGENERATE, FKStatus.BAD_INPUT):
                raise RuntimeError(f"start-up: forward kinematics failed ({fk.status.name})")
            if self.at is self.reference:  # no reference yet: the estimate is the pose
                self.reference.hold(e.position, e.rotation)
            if self.grippers.n:
                self.grippers.update(st, sense=False)
            out = dist.solve(dist.current, self.pose.gravity_hold(e.rotation), None)
            # on the way, a pose that cannot be held gives its least-violating tensions: the
            # fixed point goes on from them (from the minimum tensions, with the pose from six
            # cables, the first poses of the springy Sensors 2019 robot are far off)
            dist.total(out.tensions, d.hold_tensions)
            dist.total(out.tensions, d.stretch_tensions)
            if out.ok and d.cycle % self._stretch_every == 0:
                self._refresh_stretch_tensions()
            change = float(np.max(np.abs(d.stretch_tensions - self._last_stretch)))
            self._last_stretch[:] = d.stretch_tensions
            if change < 1e-3:
                break
        else:
            raise RuntimeError("start-up: pose and tensions did not settle in 100 iterations")
        if not out.ok:
            p = e.position
            raise RuntimeError(
                f"start-up: the estimated pose [{p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}] m "
                f"cannot be held ({out.status.name}: {out.message})"
            )
        if fk.residual > self.model.control.max_fk_residual:
            raise RuntimeError(
                f"start-up: the encoders disagree with every pose "
                f"({fk.status.name}, residual {fk.residual:.3g} m)"
            )
        d.tensions[:] = d.hold_tensions
        e.velocity[:] = 0.0
        e.omega[:] = 0.0
        self.trajectory.reset(self._pose6())
        self.reference.update(e)
        self.supervisor.set_state(
            State.READY, now, "drives inactive, feedback live, pose estimated"
        )

    def submit(self, cmd: Command) -> bool:
        """Queue a command for the next cycle; False when the mailbox is full. A command the
        loop could not act on (a pose or speed out of range, TDA options this robot cannot
        use) is refused here, with an event saying why: the cycle checks nothing twice."""
        d = self.data
        if cmd.kind is CommandKind.MOVE:
            pose = None if cmd.pose is None else np.asarray(cmd.pose, dtype=float)
            if (
                pose is None
                or pose.shape != (6,)
                or not np.all(np.isfinite(pose))
                or not (0.0 < cmd.speed <= 1.0 and 0.0 < cmd.accel <= 1.0)
            ):  # the gateway validates; this is the last guard before the trajectory
                d.events.append((d.time, "move ignored: pose or speed not finite/in range"))
                return True
            cmd.target = self.trajectory.coordinates(pose[:3], rpy_to_matrix(*pose[3:]))
            why = self._line_leaves_limits(cmd.target)
            if why:
                d.events.append((d.time, f"move ignored: {why}"))
                return True
        elif cmd.kind is CommandKind.JOG:
            if not self.jog.plan(cmd):
                return True
        elif cmd.kind is CommandKind.PATH:
            if not self.path.plan_path(cmd):
                return True
        elif cmd.kind is CommandKind.RESUME:
            if not self.path.plan_resume(cmd):
                return True
        elif cmd.kind is CommandKind.SET_TDA:
            errors = ["no options"] if cmd.tda is None else cmd.tda.validate(self.model)
            if errors:
                d.events.append((d.time, f"TDA options rejected: {'; '.join(errors)}"))
                return True
        if len(self.mailbox) >= (self.mailbox.maxlen or 0):
            return False
        self.mailbox.append(cmd)
        return True

    def _line_leaves_limits(self, target: FloatArray) -> str:
        """Where the straight line from the reference to ``target`` (coordinates) leaves the
        soft limits, or "" (``SoftLimits.ray_end``, sampled every 2 cm)."""
        start = self.trajectory.position.copy()
        end, why = self.limits.ray_end(start, target - start, 1.0, step=0.02)
        if not why:
            return ""
        where = np.round(end[:3], 4).tolist()
        return f"the line to the target leaves the soft limits after {where} m: {why}"

    # -- the cycle ---------------------------------------------------------------------------------
    def update(self, t: float, st: WinchStates) -> None:
        """One cycle at time ``t`` (s) from the drives' feedback ``st``: every output into
        ``data`` (phases 1-5 of ``PHASES`` timed)."""
        clock, d = self._clock_ns, self.data
        ph = d.phase_us
        t1 = clock()
        # the real elapsed time: after a late or missed period the integral, the trajectory,
        # the tension rate limit, the ramps and the saturation time step by what passed
        gap = t - self._last_t
        d.dt = gap if 0.0 < gap < self.MAX_STEP else self.period
        self._last_t = t
        d.time = t
        d.cycle += 1
        if not self.grippers.n:  # the known external wrench, whoever set it, from now on
            d.ext_total[:] = self.ext_wrench
        self._handle_commands(t)
        cs = self.cable_space
        if cs.enabled and d.state in OBSERVED_STATES:
            # the drives hold the lengths stretched by the commanded tensions (no pose feedback
            # in position mode, so no algebraic loop): the same tensions for the estimate
            d.stretch_tensions[:] = d.tensions
            cs.measure(st.torque, st.velocity, st.sampled_at, self.distribution.current.ns.N)
            cs.estimate_disturbance(
                self.at.kin.W,
                d.state is not State.STOPPING
                and d.saturation >= 1.0
                and self.distribution.bad_cycles == 0,
            )
            d.ext_total += d.ext_estimate  # fed forward: the pose law and the TDA see it
            cs.force_feedback(stopping=d.state is State.STOPPING)
        elif d.cycle % self._stretch_every == 0:
            self._refresh_stretch_tensions()
        e = self.estimator
        fk = e.update(st.stamp, st.position, d.stretch_tensions, st.velocity, st.feedback_age)
        if d.state in OBSERVED_STATES:
            self.observer.update(t, st.torque, st.velocity, self.trajectory.acceleration)
        if self.grippers.n:
            self.grippers.update(st, sense=True)  # ext_total: + the jaws' weight
        t2 = clock()
        ph[1] = (t2 - t1) / 1e3
        last = e.last_fk
        self.jog.update(t)
        self.path.update(t)
        self.supervisor.supervise(
            t,
            fk.status,
            last.residual if last is not None else 0.0,
            math.hypot(*e.velocity.tolist()),
            self.trajectory.finished and not self.path.holds_motion,
        )
        if d.motion and self.trajectory.finished and not self.path.holds_motion:
            d.motion = "" if self.path.plan is None else d.motion
        self.trajectory.update(self._reference_step(gap))
        if cs.enabled:
            self.reference.update(e)
        t3 = clock()
        ph[2] = (t3 - t2) / 1e3
        active = d.state in ACTIVE_STATES
        if active:
            # anti-windup: the integral holds while the feedback is saturated
            self.pose.update(d.state in HEALTHY_STATES and d.saturation >= 1.0)
        t4 = clock()
        ph[3] = (t4 - t3) / 1e3
        if active:
            out = self.distribution.distribute()
            self._count_saturation(t)
            if d.state is State.STOPPING:
                pass
            elif self.distribution.bad_cycles >= Distribution.BAD_CYCLES:
                self.supervisor.fault(
                    t,
                    FaultKind.TENSION_DISTRIBUTION,
                    f"tension distribution {out.status.name} (the feed-forward alone): "
                    f"{out.message}",
                    hold=True,
                )
            elif d.saturated_for > self.model.control.max_saturation_time:
                self.supervisor.fault(
                    t,
                    FaultKind.TENSION_DISTRIBUTION,
                    f"feedback wrench saturated for {d.saturated_for:.2f} s "
                    f"(> max_saturation_time {self.model.control.max_saturation_time:g} s; "
                    f"the cables gave {d.saturation:.0%} of it last)",
                    hold=True,
                )
        t5 = clock()
        ph[4] = (t5 - t4) / 1e3
        self.winches.update(
            d.tensions, self.at.kin.WT, self.trajectory.acceleration, st.velocity, active,
            d.torques,
        )  # fmt: skip
        if cs.enabled:
            cs.targets(active, st.position)
        ph[5] = (clock() - t5) / 1e3

    def _reference_step(self, gap: float) -> float:
        """s the reference moves on this cycle, ``gap`` s after the last. Position mode: as
        long as the drives went on at their targets' rate, then held; it waits out the rest of
        a longer stall (by all of it, the next targets stepped ahead of the held drives: a
        following-error fault, 78 ms at 0.2 m/s on rowc). Torque mode: ``data.dt``."""
        if self.cable_space.enabled and 0.0 < gap < math.inf:
            return min(gap, self._extrapolation)
        return self.data.dt

    # s: a longer gap between cycles (the first one, or after the loop stood still) steps by a
    # period: what happened meanwhile is not the controller's to integrate
    MAX_STEP = 0.1

    # Saturated time drains at this fraction of real time once the cables give the whole
    # feedback again: a loop that saturates in most of its cycles (an unstable gain chattering
    # on the limits: 60 % of the cycles on rowc tuned at 1 Hz in y, a 0.5 mm limit cycle) adds
    # up to a fault; one long push that then recovers drains away.
    SATURATION_LEAK = 0.25

    def _count_saturation(self, t: float) -> None:
        """``data.saturated_for``: the time (s, real elapsed) the feedback was saturated,
        leaking at ``SATURATION_LEAK`` while it is not; ``saturated_cycles`` in all."""
        d = self.data
        dt = d.dt
        if d.saturation < 1.0:
            d.saturated_for += dt
            d.saturated_cycles += 1
        else:
            d.saturated_for = max(0.0, d.saturated_for - self.SATURATION_LEAK * dt)

    def internal_error(self, t: float, exc: Exception) -> None:
        """The cycle failed: hold the last feasible tensions and stop the controlled way."""
        d = self.data
        d.torques[:] = self.winches.r * d.hold_tensions
        self.supervisor.fault(
            t, FaultKind.INTERNAL, f"internal error: {type(exc).__name__}: {exc}", hold=True
        )

    def _refresh_stretch_tensions(self) -> None:
        e, tr, pf, ff = self.estimator, self.trajectory, self.model.platform, self._ff_wrench
        ff[:] = self.pose.gravity_hold(e.rotation)
        if self.data.state in (State.ENABLED, State.MOVING, State.STOPPING):
            ff[:3] += pf.mass * tr.acceleration[:3]
            ff[3:] += e.rotation @ pf.inertia @ e.rotation.T @ tr.acceleration[3:]
        self.distribution.stretch(ff)

    def _pose6(self) -> FloatArray:
        return self.trajectory.coordinates(self.estimator.position, self.estimator.rotation)

    # -- commands (acceptance: commands.ACCEPTED_IN) -----------------------------------------------
    def _handle_commands(self, t: float) -> None:
        d = self.data
        while self.mailbox:
            cmd = self.mailbox.popleft()
            if accepted(cmd.kind, d.state):
                self._handlers[cmd.kind](t, cmd)
            else:
                d.events.append((t, f"command {cmd.kind.value} ignored in state {d.state.value}"))

    def _enable(self, t: float, cmd: Command) -> None:
        drv, d = self.drives, self.data
        if drv.lifecycle is not Lifecycle.INACTIVE:
            # a drive fault came back after the reset: the supervisor faults next
            d.events.append((t, f"enable refused: drives {drv.lifecycle.value} {drv.error}"))
            return
        self.trajectory.reset(self._pose6())
        self.reference.restart()
        d.tensions[:] = d.hold_tensions
        self.pose.reset()
        self.observer.reset()
        self.cable_space.start_measuring()
        # a fresh start: the saturation of before the fault is not this run's
        d.saturation, d.saturated_for = 1.0, 0.0
        self.grippers.hold()
        drv.begin_activate()
        self.supervisor.set_state(State.ENABLING, t, "enabling the drives with holding torques")

    def _disable(self, t: float, cmd: Command) -> None:
        self.supervisor.set_state(State.DISABLING, t, "disable requested")

    def _stop(self, t: float, cmd: Command) -> None:
        self.path.abort(t)
        self.jog.active = False
        self.trajectory.stop_here()
        self.supervisor.set_state(State.ENABLED, t, "stop: decelerating, then holding")

    def _reset(self, t: float, cmd: Command) -> None:
        self.drives.begin_recover()
        self.supervisor.clear_fault()
        self.trajectory.reset(self._pose6())
        self.supervisor.set_state(State.READY, t, "fault reset")

    def _move(self, t: float, cmd: Command) -> None:
        if cmd.target is None or cmd.pose is None:  # not through submit(): nothing to act on
            return
        self.path.abort(t)
        self.jog.active = False
        self.trajectory.set_target(cmd.target, cmd.speed, cmd.accel)
        self.data.motion = "move"
        self.supervisor.set_state(State.MOVING, t, f"move to {np.round(cmd.pose, 4).tolist()}")

    def _jog(self, t: float, cmd: Command) -> None:
        d = self.data
        if self.path.plan is not None:
            d.events.append((t, "jog ignored: a path is running (pause or abort it first)"))
            return
        self.jog.command(t, cmd)
        if self.jog.active and d.state is not State.MOVING:
            self.supervisor.set_state(State.MOVING, t, "jog")

    def _path(self, t: float, cmd: Command) -> None:
        d = self.data
        plan, offset = cmd.plan
        if not self.trajectory.finished or not plan.starts_at(self.trajectory.position):
            d.events.append((t, f"path {plan.name} not started: the robot moved since it was "
                             "checked"))  # fmt: skip
            return
        self.path.start(t, plan, offset)
        self.supervisor.set_state(State.MOVING, t, f"path {plan.name}: {plan.summary()}")

    def _pause(self, t: float, cmd: Command) -> None:
        if self.path.plan is None or self.path.paused:
            self.data.events.append((t, "pause ignored: no running path"))
            return
        self.path.pause(t)

    def _resume(self, t: float, cmd: Command) -> None:
        if not self.path.paused or cmd.plan is None:
            self.data.events.append((t, "resume ignored: no paused path"))
            return
        plan, offset = cmd.plan
        self.path.start(t, plan, offset)
        self.supervisor.set_state(State.MOVING, t, f"path {plan.name} resumed at segment "
                                  f"{offset + 1}")  # fmt: skip

    def _abort(self, t: float, cmd: Command) -> None:
        self.path.abort(t)
        self.jog.stop()

    def _set_tda(self, t: float, cmd: Command) -> None:
        d, opts = self.data, cmd.tda
        if opts is None:
            return
        if opts == self.distribution.options:
            # the same options again (an operator's retry, a script): no switch, no blend
            d.events.append((t, f"TDA method {opts.method.value} unchanged"))
            return
        # the stretch estimate assumes the tensions the cables now get: both switch
        self.distribution.switch(opts, t, blend=d.state in HEALTHY_STATES)
        d.events.append((t, f"TDA method {opts.method.value}"))

    # -- what outside readers use ----------------------------------------------------------------
    @property
    def state(self) -> State:
        return self.data.state

    @property
    def fault_reason(self) -> str:
        return self.data.fault_reason

    @property
    def fault_kind(self) -> FaultKind | None:
        return self.data.fault_kind

    @property
    def events(self) -> collections.deque[tuple[float, str]]:
        return self.data.events

    @property
    def tensions(self) -> FloatArray:
        return self.data.tensions

    @property
    def hold_tensions(self) -> FloatArray:
        return self.data.hold_tensions

    @property
    def torques(self) -> FloatArray:
        return self.data.torques

    @property
    def wrench(self) -> FloatArray:
        return self.data.wrench

    @property
    def pose_error(self) -> FloatArray:
        return self.data.pose_error

    @property
    def tda_status(self) -> Any:
        return self.data.tda_status

    @property
    def cycle(self) -> int:
        return self.data.cycle

    @property
    def time(self) -> float:
        return self.data.time

    @property
    def phase_us(self) -> FloatArray:
        return self.data.phase_us

    @property
    def tda(self) -> Any:
        """The distributor in use (its ``options``)."""
        return self.distribution.current

    @property
    def t_min(self) -> FloatArray:
        return self.distribution.t_min

    @property
    def t_max(self) -> FloatArray:
        return self.distribution.t_max

    @property
    def grasp(self) -> Any:
        return self.grippers.grasp

    @property
    def grip_target(self) -> FloatArray:
        return self.data.grip_target

    def gripper_range(self, j: int) -> tuple[float, float]:
        return self.grippers.travel_range(j)

    def impose(self, impositions: Any) -> None:
        self.distribution.impose(impositions)

    def status(self) -> dict[str, Any]:
        d = self.data
        return {
            "state": d.state.value,
            "fault": d.fault_reason,
            "fault_kind": d.fault_kind.value if d.fault_kind is not None else "",
            "position": d.position.tolist(),
            "tensions": d.tensions.tolist(),
            "tda_status": d.tda_status.name,
            "cycle": d.cycle,
            **({"grippers": self.grippers.status()} if self.grippers.n else {}),
        }
