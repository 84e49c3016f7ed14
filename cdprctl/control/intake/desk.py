"""The command desk: what an operator asks of the controller, checked on the way in and acted
on at the start of the next cycle.

``submit`` (outside the loop: the gateway's process hands commands to the daemon's I/O thread,
tests and scripts call it directly) checks a command's payload and plans what needs planning
(a move's line, a jog's segment, a path), and answers with a ``Verdict``: accepted into the
mailbox, or refused with the reason (also an event). ``handle`` (in the cycle) acts on each
queued command whose kind the state accepts (``commands.ACCEPTED_IN``), through the handlers
below; the cycle checks nothing twice. One rule decides which motion source moves the
reference (``_take_motion``). The desk sees the controller through its ports (``DeskPorts``):
what it asks, named, not the controller."""

from __future__ import annotations

import collections
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprctl.control.command_types import (
    NOTHING,
    Command,
    CommandKind,
    GripperCommand,
    JogCommand,
    MoveCommand,
    PathCommand,
    Plan,
    SetTdaCommand,
    StopCommand,
    accepted,
)
from cdprctl.control.cycle.distribution import Distribution
from cdprctl.control.cycle.gripper_control import GripperControl
from cdprctl.control.data import ControlData
from cdprctl.control.intake.jog import Jog
from cdprctl.control.intake.path_follower import PathFollower
from cdprctl.control.states import HEALTHY_STATES, State
from cdprctl.control.supervision.drive_port import DrivePort
from cdprctl.control.supervision.state_machine import StateMachine
from cdprctl.control.supervision.supervisor import Supervisor
from cdprctl.core.realtime import sharing_the_interpreter
from cdprctl.core.rotation import FloatArray, rpy_to_matrix
from cdprctl.model.robot import RobotModel
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.trajectory import Trajectory
from drivers.vocabulary import Lifecycle


@dataclass(frozen=True)
class DeskPorts:
    """What the desk works with, handed over by the controller: the loop's data and the
    state machine it asks; the drives' lifecycle; the trajectory and the motion sources a
    command moves, the soft limits it is checked against; the supervisor's stops and faults;
    the distribution a TDA switch changes; the grippers; ``restart()`` the cycle's stages
    afresh at the holding pose (enable); ``pose6()`` the estimated pose as trajectory
    coordinates."""

    model: RobotModel
    data: ControlData
    machine: StateMachine
    drives: DrivePort
    trajectory: Trajectory
    limits: SoftLimits
    jog: Jog
    path: PathFollower
    supervisor: Supervisor
    distribution: Distribution
    grippers: GripperControl
    restart: Callable[[], None]
    pose6: Callable[[], FloatArray]


@dataclass(frozen=True)
class Verdict:
    """What ``submit`` did with a command: queued for the next cycle, or refused (why)."""

    accepted: bool
    reason: str = ""

    def __bool__(self) -> bool:
        return self.accepted


ACCEPTED = Verdict(True)
MAILBOX = 64  # commands waiting for the next cycle at most
FULL = Verdict(False, "the command mailbox is full")


class CommandDesk:
    def __init__(self, ctl: DeskPorts):
        self.ctl = ctl  # the controller's ports: the only way the desk reaches it
        self.data = ctl.data
        self.machine = ctl.machine  # the state changes the commands ask for
        # each command queued with what submit planned for it
        self.mailbox: collections.deque[tuple[Command, Plan]] = collections.deque(maxlen=MAILBOX)
        # one handler per kind, each taking its kind's type (``command_types.py``)
        self._handlers: dict[CommandKind, Callable[[float, Any, Plan], None]] = {
            CommandKind.ENABLE: self._enable,
            CommandKind.DISABLE: self._disable,
            CommandKind.STOP: self._stop,
            CommandKind.RESET: self._reset,
            CommandKind.MOVE: self._move,
            CommandKind.SET_TDA: self._set_tda,
            CommandKind.GRIPPER: self._gripper,
            CommandKind.JOG: self._jog,
            CommandKind.PATH: self._path,
            CommandKind.PAUSE: self._pause,
            CommandKind.RESUME: self._resume,
            CommandKind.ABORT: self._abort,
        }

    # -- outside the loop ------------------------------------------------------------------------
    def submit(self, cmd: Command) -> Verdict:
        """Queue ``cmd`` for the next cycle, or refuse it (a pose or speed out of range, a path
        the limits refuse, TDA options this robot cannot use, a full mailbox): the reason is
        in the verdict and, except for a full mailbox, an event. Runs beside the loop (the
        daemon's I/O thread): a path's or a resume's plan checks thousands of samples, so the
        interpreter's lock is shared in short turns meanwhile."""
        with sharing_the_interpreter():
            plan = self._plan(cmd)
        if plan is None:
            return Verdict(False, self.data.events[-1][1])
        if len(self.mailbox) >= MAILBOX:
            return FULL
        self.mailbox.append((cmd, plan))
        return ACCEPTED

    def _plan(self, cmd: Command) -> Plan | None:
        """What ``cmd`` needs planned (``NOTHING`` for most kinds), or None when it cannot be
        acted on (why: written as an event)."""
        c, d = self.ctl, self.data
        if isinstance(cmd, MoveCommand):
            pose = None if cmd.pose is None else np.asarray(cmd.pose, dtype=float)
            if (
                pose is None
                or pose.shape != (6,)
                or not np.all(np.isfinite(pose))
                or not (0.0 < cmd.speed <= 1.0 and 0.0 < cmd.accel <= 1.0)
            ):  # the gateway validates; this is the last guard before the trajectory
                d.events.append((d.time, "move ignored: pose or speed not finite/in range"))
                return None
            target = c.trajectory.coordinates(pose[:3], rpy_to_matrix(*pose[3:]))
            # the gateway refused it already from the snapshot's reference; this one holds now
            why = c.limits.line_refusal(c.trajectory.position, target)
            if why:
                said = (np.round(pose, 4) + 0.0).tolist()  # which move: a demo's are unsaid
                d.events.append((d.time, f"move to {said} ignored: {why}"))
                return None
            return Plan(target=target)
        if isinstance(cmd, JogCommand):
            why = self._take_motion(d.time, "jog", ask_only=True)  # again in the cycle: a
            if why:  # path may end meanwhile
                d.events.append((d.time, f"jog ignored: {why}"))
                return None
            return c.jog.plan(cmd, c.trajectory, c.limits)
        if isinstance(cmd, PathCommand):
            return c.path.plan_path(cmd, c.trajectory, c.limits)
        if cmd.kind is CommandKind.RESUME:
            return c.path.plan_resume(c.trajectory, c.limits)
        if isinstance(cmd, SetTdaCommand):
            errors = ["no options"] if cmd.tda is None else cmd.tda.validate(c.model)
            if errors:
                d.events.append((d.time, f"TDA options rejected: {'; '.join(errors)}"))
                return None
        return NOTHING

    # -- in the cycle ------------------------------------------------------------------------------
    def handle(self, t: float) -> None:
        d = self.data
        while self.mailbox:
            cmd, plan = self.mailbox.popleft()
            if accepted(cmd.kind, d.state):
                self._handlers[cmd.kind](t, cmd, plan)
            else:
                d.events.append((t, f"command {cmd.kind.value} ignored in state {d.state.value}"))

    def _take_motion(self, t: float, by: str, ask_only: bool = False) -> str:
        """One source moves the reference at a time. A move or a stop (``by``) takes over
        from a path (braked and forgotten) and a jog; a jog does not take over a path (pause
        or abort it first). Returns why ``by`` may not, or ""; ``ask_only``: change nothing."""
        c = self.ctl
        if by == "jog":
            return "a path is running (pause or abort it first)" if c.path.plan is not None else ""
        if not ask_only:
            c.path.abort(t, c.trajectory)
            c.jog.active = False
        return ""

    def motion_ended(self, standing: bool) -> None:
        """In the cycle, after the motion sources: ``data.motion`` back to holding ("") once
        the reference stands (``standing``: the trajectory finished, no path between
        segments or dwelling) and no path is left to play."""
        if standing and self.data.motion and self.ctl.path.plan is None:
            self.data.motion = ""

    def _enable(self, t: float, cmd: Command, plan: Plan) -> None:
        c, d = self.ctl, self.data
        if c.drives.lifecycle is not Lifecycle.INACTIVE:
            # a drive fault came back after the reset: the supervisor faults next
            d.events.append((t, f"enable refused: drives {c.drives.lifecycle.value} "
                             f"{c.drives.error}"))  # fmt: skip
            return
        c.restart()  # every stage afresh from the holding pose (Controller.restart)
        c.drives.begin_activate()
        self.machine.request(State.ENABLING, t, "enabling the drives with holding torques")

    def _still_stopping(self, t: float, cmd: Command) -> bool:
        """A fault's stop under way: a reset or disable waits until a category 2 stop holds."""
        if self.data.state is not State.STOPPING or self.ctl.supervisor.holding_after_stop(t):
            return False
        self.data.events.append((t, f"{cmd.kind.value} refused: the controlled stop (category "
                                 f"{self.data.stop_category}) is under way"))  # fmt: skip
        return True

    def _disable(self, t: float, cmd: Command, plan: Plan) -> None:
        """Decelerate to rest, then disable (the supervisor, once the trajectory stands):
        the holding brakes are not for stopping a moving platform (a category 1 stop)."""
        if self._still_stopping(t, cmd):
            return
        if self.data.state is State.STOPPING:  # a category 2 stop holding: taken as its end
            self.ctl.supervisor.clear_fault()
        self._take_motion(t, "stop")
        self.ctl.trajectory.stop_here()
        self.ctl.supervisor.stop_asked(1)
        self.machine.request(State.DISABLING, t, "disable requested: decelerating, "
                             "then the drives disabled")  # fmt: skip

    def _stop(self, t: float, cmd: StopCommand, plan: Plan) -> None:
        """IEC 60204-1's categories: 0 the drives off at once (the brakes stop the platform),
        1 decelerate then disable (``disable``), 2 decelerate and hold, powered."""
        d, sup = self.data, self.ctl.supervisor
        if cmd.category == 0:
            self._take_motion(t, "stop")
            sup.off(t, State.READY, "stop category 0: the drives disabled at once, the brakes "
                     "stop the platform")  # fmt: skip
        elif cmd.category == 1:
            if d.state is not State.DISABLING:
                self._disable(t, cmd, plan)
        elif d.state in (State.ENABLED, State.MOVING):
            self._take_motion(t, "stop")
            self.ctl.trajectory.stop_here()
            sup.stop_asked(2)
            self.machine.request(State.ENABLED, t, "stop: decelerating, then holding")
        else:
            d.events.append((t, f"stop category 2 ignored in {d.state.value}"))

    def _reset(self, t: float, cmd: Command, plan: Plan) -> None:
        c, d = self.ctl, self.data
        if self._still_stopping(t, cmd):
            return
        c.supervisor.stop_asked(-1)
        if d.state is State.STOPPING:  # a category 2 stop holding: back to holding, enabled
            c.supervisor.clear_fault()
            c.trajectory.reset(c.pose6())
            self.machine.request(State.ENABLED, t, "fault reset: holding the pose")
            return
        # from the e-stop the drives take the reset only once the chain is closed; else they
        # report it again and the e-stop says so
        if d.state is State.ESTOP:
            c.supervisor.estop.reset_at = t
        c.drives.begin_recover()
        c.supervisor.clear_fault()
        c.trajectory.reset(c.pose6())
        self.machine.request(State.READY, t, "fault reset")

    def _move(self, t: float, cmd: MoveCommand, plan: Plan) -> None:
        if plan.target is None or cmd.pose is None:  # not through submit(): nothing to act on
            return
        c = self.ctl
        self._take_motion(t, "move")
        c.trajectory.set_target(plan.target, cmd.speed, cmd.accel)
        self.data.motion = "move"
        self.machine.request(State.MOVING, t, f"move to {np.round(cmd.pose, 4).tolist()}")

    def _jog(self, t: float, cmd: JogCommand, plan: Plan) -> None:
        c, d = self.ctl, self.data
        why = self._take_motion(t, "jog")
        if why:
            d.events.append((t, f"jog ignored: {why}"))
            return
        if c.jog.command(t, plan, c.trajectory):  # a segment to follow
            d.motion = "jog"
        if c.jog.active and d.state is not State.MOVING:
            self.machine.request(State.MOVING, t, "jog")

    def _path(self, t: float, cmd: PathCommand, plan: Plan) -> None:
        c, d = self.ctl, self.data
        assert plan.path is not None  # submit planned it
        path, offset = plan.path
        if not c.trajectory.finished or not path.starts_at(c.trajectory.position):
            d.events.append((t, f"path {path.name} not started: the robot moved since it was "
                             "checked"))  # fmt: skip
            return
        c.path.start(t, path, offset, c.trajectory)
        d.motion = "path"
        self.machine.request(State.MOVING, t, f"path {path.name}: {path.summary()}")

    def _pause(self, t: float, cmd: Command, plan: Plan) -> None:
        path = self.ctl.path
        if path.plan is None or path.paused:
            self.data.events.append((t, "pause ignored: no running path"))
            return
        path.pause(t, self.ctl.trajectory)

    def _resume(self, t: float, cmd: Command, plan: Plan) -> None:
        c = self.ctl
        if not c.path.paused or plan.path is None:
            self.data.events.append((t, "resume ignored: no paused path"))
            return
        path, offset = plan.path
        c.path.start(t, path, offset, c.trajectory)
        self.data.motion = "path"
        self.machine.request(State.MOVING, t, f"path {path.name} resumed at segment "
                             f"{offset + 1}")  # fmt: skip

    def _abort(self, t: float, cmd: Command, plan: Plan) -> None:
        self.ctl.path.abort(t, self.ctl.trajectory)
        self.ctl.jog.stop(self.ctl.trajectory)

    def _gripper(self, t: float, cmd: GripperCommand, plan: Plan) -> None:
        self.ctl.grippers.command(t, cmd)

    def _set_tda(self, t: float, cmd: SetTdaCommand, plan: Plan) -> None:
        c, d, opts = self.ctl, self.data, cmd.tda
        if opts is None:
            return
        if opts == c.distribution.options:
            # the same options again (an operator's retry, a script): no switch, no blend
            d.events.append((t, f"TDA method {opts.method.value} unchanged"))
            return
        # the stretch estimate assumes the tensions the cables now get: both switch
        c.distribution.switch(opts, t, blend=d.state in HEALTHY_STATES)
        d.events.append((t, f"TDA method {opts.method.value}"))
