"""The supervisor: the checks that stop the robot, and the transitions they ask of the state
machine (``state_machine.py``: the table, the one owner of the state).

::

    INIT ─startup→ READY ─enable→ ENABLING ─drives on→ ENABLED ⇄ MOVING (move / finished)
    ENABLED/MOVING ─stop→ ENABLED (decelerated, holding)
    ENABLING/ENABLED/MOVING ─disable→ DISABLING (decelerating) → READY (at rest: brakes off)
    ENABLING/ENABLED/MOVING/DISABLING ─stop category 0→ READY (drives off at once: brakes)
    any ─fault→ STOPPING (hold the pose with feasible tensions, stop_duration) → FAULT
    STOPPING (category 2, after stop_duration: holding, powered) ─reset→ ENABLED, ─disable→
    DISABLING
    FAULT ─reset→ READY (drive faults reset, drives disabled)
    any but INIT ─the drives report safe torque off→ ESTOP ─reset, the chain closed→ READY

Each fault kind takes its stop category (``[safety.stop_category]``, model/safety.py): 0
skips STOPPING (a driver fault: the drives are not to be trusted, their brakes close), 1 holds
then disables, 2 holds powered until a reset or disable, watched meanwhile. An open
safety chain (``SafeTorqueOffError``) is no fault: the e-stop state (``estop.py``), no FAULT,
no re-enable until a reset the drives take. Every fault has a ``FaultKind``;
``states.PERSISTENCE`` says why it is immediate or what must persist. Nothing here raises or
allocates but the event text of a transition, a fault or the e-stop.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cdprctl.control.data import ControlData
from cdprctl.control.states import (
    DISABLING,
    ENABLED,
    ENABLING,
    ESTOP,
    FAULT,
    MOVING,
    READY,
    STOPPING,
    FaultKind,
    State,
)
from cdprctl.control.supervision.cable_checks import TensionDisagreement
from cdprctl.control.supervision.clearance_watch import ClearanceWatch
from cdprctl.control.supervision.drive_port import DrivePort, driver_fault_kind
from cdprctl.control.supervision.estop import EmergencyStop
from cdprctl.control.supervision.persistence import Persistence
from cdprctl.control.supervision.state_machine import TRANSITIONS as TRANSITIONS
from cdprctl.control.supervision.state_machine import StateMachine
from cdprctl.core.numerics import largest, max2, worst_ratio
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.forward_kinematics import FKStatus
from cdprctl.model.control import ControlConfig
from cdprctl.model.safety import SafetyConfig
from drivers.errors import DriveFaultError, SafeTorqueOffError
from drivers.vocabulary import ACTIVE, ERROR

# bound once (on 3.11 reading an enum member builds a method wrapper: states.py)
_FK_FAILED = (FKStatus.DEGENERATE, FKStatus.BAD_INPUT)
# m: the estimated position where a caller gives none (a test of the checks alone)
_NOWHERE = np.zeros(3)
_NOWHERE.flags.writeable = False


class Supervisor:
    # The estimated speed must stay over the limit this long: taking over from the brakes moves
    # the drums for a few ms while the cables find their tensions, and in a badly conditioned
    # direction that is a short, false spike of estimated speed (seen across processes after
    # a restart: 2 of 10). A real runaway at the limit goes 30 mm further before the stop.
    OVER_SPEED_FOR = 0.03  # s
    # A drive at its torque limit this long (position mode): beyond what the cables hold
    TORQUE_FOR = 0.03  # s
    AT_LIMIT = 0.98  # of the torque limit
    ENABLE_TIMEOUT = 2.0  # s
    # m/s: the estimated speed under which a disabled platform is at rest (the reference
    # stands before the platform does: in torque mode the pose loop lags it by tens of mm)
    AT_REST = 0.005

    def __init__(self, config: ControlConfig, data: ControlData, drives: DrivePort,
                 tension_limits: np.ndarray | None = None,
                 torque_limits: np.ndarray | None = None,
                 safety: SafetyConfig | None = None,
                 machine: StateMachine | None = None,
                 clearance: ClearanceWatch | None = None):  # fmt: skip
        """``tension_limits`` (N, per cable): the internal tension error that faults (position
        mode), None: not checked; ``safety``: each fault kind's stop category; ``machine``:
        the state machine its transitions are asked of (the controller's; None: its own);
        ``clearance``: the cables' clearance check (None: not checked)."""
        self.config = config
        safety = safety or SafetyConfig()
        self.stop_of = {k: safety.category_of(k.value) for k in FaultKind}
        self.tension_limits = tension_limits
        self._tension = TensionDisagreement(config, tension_limits)
        # N·m per winch: the limit a drive sitting at means the load is beyond the cables
        # (position mode), None: not checked
        self.torque_limits = torque_limits
        self._torque_at_limit = Persistence(self.TORQUE_FOR)
        self._at_limit = False  # a drive at its torque limit this cycle
        self.data = data
        self.drives = drives
        # a controlled stop asked of the trajectory (``take_stop``: the controller brakes it)
        self._stop_asked = False
        # s: the longest a disable decelerates before the brakes close anyway (a trajectory
        # that never stands must not keep the drives on): twice the limits' own stop time
        # (a jerk-limited stop from the top speed takes v/a + a/j), at least 3 s
        c = config
        stop = max(c.max_velocity / c.max_acceleration + c.max_acceleration / c.max_jerk,
                   c.max_angular_velocity / c.max_angular_acceleration
                   + c.max_angular_acceleration / c.max_angular_jerk)  # fmt: skip
        self.disable_within = max(3.0, 2.0 * stop)
        self._stop_until = 0.0
        self._speed_over = Persistence(self.OVER_SPEED_FOR)
        # old feedback at two reads in a row: after a stall of the loop itself (no SYNC went
        # out, the drives could not answer) the first read finds it old and the next fresh —
        # seed000_grippers at 500 Hz stopped once on 64 ms after such a stall; drives that
        # really fall silent are the driver's (feedback_timeout, over running cycles)
        self._feedback_old = Persistence(config.period)
        self.estop = EmergencyStop()
        self.machine = machine if machine is not None else StateMachine(data)
        self.clearance = clearance
        self.machine.forget_when_unsupervised(
            (self._tension.over, self._torque_at_limit, self._speed_over, self._feedback_old)
            + (() if clearance is None else (clearance,))
        )

    @property
    def state(self) -> State:
        return self.data.state

    @property
    def t_state(self) -> float:
        """s, when the state was entered (the state machine's)."""
        return self.machine.entered

    @t_state.setter
    def t_state(self, t: float) -> None:  # a test's start of the enable time-out
        self.machine.entered = t

    def set_state(self, s: State, t: float, why: str) -> None:
        """A transition asked of the state machine (``StateMachine.request``), as the checks
        here ask it; for a test that drives the supervisor by hand."""
        self.machine.request(s, t, why)

    def fault(self, t: float, kind: FaultKind, reason: str) -> None:
        """Stop the robot for ``reason`` by the category ``kind`` takes: hold the pose with
        feasible tensions for ``stop_duration`` (1, then disable; 2, holding on) when the
        drives can, else disable at once (0)."""
        d = self.data
        if d.state in (FAULT, STOPPING):
            return
        d.fault_reason = reason
        d.fault_kind = kind
        d.events.append((t, f"FAULT: {reason}"))
        d.faults.append((t, kind))
        category = self.stop_of[kind]
        if category > 0 and self.drives.lifecycle is ACTIVE:
            d.stop_category = category
            self._stop_asked = True
            self._stop_until = t + self.config.stop_duration
            self.machine.request(STOPPING, t, f"controlled stop, holding the pose (category "
                           f"{category})")  # fmt: skip
        else:
            self.off(t, FAULT, "drives disabled, brakes closed")

    def off(self, t: float, s: State, why: str) -> None:
        """Category 0: the drives disabled at once, the brakes stop and hold the platform."""
        self.data.stop_category = 0
        self.drives.begin_deactivate()
        self.machine.request(s, t, why)

    def take_stop(self) -> bool:
        """Whether a fault since the last call asked for the controlled stop (the reference
        braked to rest where it is: ``Trajectory.stop_here``, the caller's to do at once)."""
        asked, self._stop_asked = self._stop_asked, False
        return asked

    def holding_after_stop(self, t: float) -> bool:
        """A category 2 stop done: holding the pose powered until a reset or disable."""
        d = self.data
        return d.state is STOPPING and d.stop_category == 2 and t >= self._stop_until

    def restart(self) -> None:
        """Enable: no stop since, and the saturation of before a fault not this run's."""
        self.data.saturated_for = 0.0
        self.data.stop_category = -1

    def stop_asked(self, category: int) -> None:
        """A stop the operator asked for (``CommandDesk``): 1 decelerate then disable, 2
        decelerate and hold; -1 none since a reset (docs/safety.md)."""
        self.data.stop_category = category

    def clear_fault(self) -> None:
        self.data.fault_reason = ""
        self.data.fault_kind = None

    def supervise(
        self,
        t: float,
        fk_status: FKStatus,
        fk_residual: float,
        speed: float,
        trajectory_finished: bool,
        position: FloatArray = _NOWHERE,
    ) -> None:
        """One cycle's checks, in order of precedence (``speed``: m/s, ``position``: m, base
        frame, both estimated)."""
        d, drv = self.data, self.drives
        if d.state is ESTOP:
            said = self.estop.watch(t, position, speed)
            if said is not None:
                d.events.append((t, said))
            return
        err = drv.error
        if drv.lifecycle is ERROR and isinstance(err, DriveFaultError) and (
            isinstance(err, SafeTorqueOffError) or self.estop.refused(t, err)
        ):
            d.events.append((t, self.estop.enter(t, position, err)))
            # the drives do not say when the chain closes (they stay in fault until a reset)
            d.fault_reason = "emergency stop: the safety chain opened; reset once it is closed"
            d.fault_kind = None
            self.off(t, ESTOP, "the drives' safety chain is open")
            return
        if drv.lifecycle is ERROR and d.state is not FAULT:
            if d.state is STOPPING:  # the drives failed during the controlled stop
                d.events.append((t, f"FAULT during the stop: drives: {drv.error}"))
                d.faults.append((t, FaultKind.DURING_STOP))
                self.off(t, FAULT, "drives disabled, brakes closed")
            else:
                self.fault(t, driver_fault_kind(drv.error), f"drives: {drv.error}")
            return
        if d.state is ENABLING:
            if drv.lifecycle is ACTIVE:
                self.machine.request(ENABLED, t, "drives enabled, holding the pose")
            elif t - self.t_state > self.ENABLE_TIMEOUT:
                why = f"drives not enabled within {self.ENABLE_TIMEOUT:g} s"
                self.fault(t, FaultKind.ENABLE_TIMEOUT, why)
            return
        if d.state is DISABLING:
            at_rest = trajectory_finished and speed < self.AT_REST
            if at_rest or t - self.t_state > self.disable_within:  # else: decelerating
                drv.begin_deactivate()
                why = "" if at_rest else f" (not at rest after {self.disable_within:g} s)"
                self.machine.request(READY, t, f"drives disabled, brakes closed{why}")
                return
        if self.torque_limits is not None and d.state in (
            ENABLED, MOVING, STOPPING, DISABLING
        ):
            beyond = self._beyond_capacity(t)
            if beyond is not None:
                self._brake_now(t, beyond)
                return
        if d.state is STOPPING:
            if t < self._stop_until:
                return
            if d.stop_category != 2:
                drv.begin_deactivate()
                self.machine.request(FAULT, t, "stopped; drives disabled, brakes closed")
                return
            failure = self._motion_failure(t, fk_status, fk_residual, speed)  # SS2: watched
            if failure is not None:
                d.events.append((t, f"FAULT during the stop: {failure[1]}"))
                d.faults.append((t, FaultKind.DURING_STOP))
                self.off(t, FAULT, "drives disabled, brakes closed")
            return
        if d.state not in (ENABLED, MOVING, DISABLING):
            return
        if d.state is MOVING and trajectory_finished:
            paused = d.path_state == "paused"  # braked onto the path: not its target
            self.machine.request(ENABLED, t, "path paused, holding" if paused else "target reached")
        failure = self._motion_failure(t, fk_status, fk_residual, speed)
        if failure is not None:
            self.fault(t, failure[0], failure[1])

    def _motion_failure(
        self, t: float, fk_status: FKStatus, fk_residual: float, speed: float
    ) -> tuple[FaultKind, str] | None:
        """The first check that fails while holding or moving, in order of precedence."""
        c = self.config
        # plain floats: five numpy reductions here cost ~15 µs a cycle; no list either
        age = largest(self.drives.states.feedback_age)
        pe = self.data.pose_error
        position_error = math.hypot(pe.item(0), pe.item(1), pe.item(2))
        angle_error = math.hypot(pe.item(3), pe.item(4), pe.item(5))
        if fk_status in _FK_FAILED:
            return FaultKind.FORWARD_KINEMATICS, f"forward kinematics {fk_status.name}"
        if fk_residual > c.max_fk_residual:
            return FaultKind.ENCODERS_DISAGREE, (
                f"the encoders disagree with every pose: forward-kinematics residual "
                f"{fk_residual * 1e3:.2f} mm > {c.max_fk_residual * 1e3:.0f} mm "
                "(an encoder jump, a slipped or broken cable)"
            )
        why = None if self.clearance is None else self.clearance.check(t)
        if why is not None:
            return FaultKind.CLEARANCE, why
        if position_error > c.max_position_error:
            return FaultKind.TRACKING, (
                f"tracking error {position_error * 1e3:.1f} mm "
                f"> {c.max_position_error * 1e3:.1f} mm"
            )
        if angle_error > c.max_angle_error:
            return FaultKind.ORIENTATION, (
                f"orientation error {angle_error:.3f} rad > {c.max_angle_error:.3f} rad"
            )
        if self._over_speed(t, speed, c.max_speed):
            return FaultKind.OVER_SPEED, (
                f"platform speed {speed:.2f} m/s > {c.max_speed:.2f} m/s "
                f"for {self.OVER_SPEED_FOR * 1e3:.0f} ms"
            )
        if self._feedback_old.held(t, age > c.max_feedback_age):
            return FaultKind.FEEDBACK_AGE, (
                f"feedback {age * 1e3:.1f} ms old > {c.max_feedback_age * 1e3:.0f} ms"
            )
        if self.tension_limits is not None:
            why = self._tension.check(t, self.data.internal_tension_error,
                                      self.data.internal_leverage, self._at_limit)  # fmt: skip
            return None if why is None else (FaultKind.CABLE_TENSION, why)
        return None

    def _beyond_capacity(self, t: float) -> str | None:
        """Why the load is beyond what the cables hold: a drive at its torque limit for
        ``TORQUE_FOR`` (``FaultKind.BEYOND_CAPACITY``), else None."""
        tau, lim = self.drives.states.torque, self.torque_limits
        assert lim is not None
        i = worst_ratio(tau, lim)
        # item: plain floats (an element as a numpy scalar was a block each cycle)
        self._at_limit = abs(tau.item(i)) >= self.AT_LIMIT * lim.item(i)
        if not self._torque_at_limit.held(t, self._at_limit):
            return None
        return (
            f"beyond capacity: the drive of cable index {i} at its torque limit "
            f"({float(tau[i]):+.2f} of ±{lim[i]:.2f} N·m) for {self.TORQUE_FOR * 1e3:.0f} ms: "
            "the cables cannot hold the platform; brakes closed at once"
        )

    def _brake_now(self, t: float, reason: str) -> None:
        """Disable at once (the brakes hold more than the motors), also during a stop."""
        d = self.data
        if d.state is STOPPING:
            d.events.append((t, f"FAULT during the stop: {reason}"))
            d.faults.append((t, FaultKind.BEYOND_CAPACITY))
            self.off(t, FAULT, "drives disabled, brakes closed")
        else:
            self.fault(t, FaultKind.BEYOND_CAPACITY, reason)

    # infeasible wrenches in a row before the supervisor faults (the last feasible tensions
    # are held meanwhile): a one-cycle spike of the PID is not a fault
    BAD_CYCLES = 3
    # Saturated time drains at this fraction of real time once the cables give the whole
    # feedback again: a loop that saturates in most of its cycles (an unstable gain chattering
    # on the limits: 60 % of the cycles on rowc tuned at 1 Hz in y, a 0.5 mm limit cycle) adds
    # up to a fault; one long push that then recovers drains away.
    SATURATION_LEAK = 0.25

    def distribution(self, t: float, bad_cycles: int, out: Any) -> None:
        """After the cycle's tension distribution (``bad_cycles`` in a row with no feasible
        feed-forward, ``out`` its last ``TDAOutput``): the saturated time counted
        (``data.saturated_for``, s of real elapsed time, leaking at ``SATURATION_LEAK``; and
        ``saturated_cycles``), then a controlled stop when the feed-forward stays infeasible or
        the feedback stays saturated beyond ``max_saturation_time``."""
        d = self.data
        if d.saturation < 1.0:
            d.saturated_for += d.dt
            d.saturated_cycles += 1
        else:
            d.saturated_for = max2(0.0, d.saturated_for - self.SATURATION_LEAK * d.dt)
        if d.state is STOPPING:
            return
        if bad_cycles >= self.BAD_CYCLES:
            self.fault(t, FaultKind.TENSION_DISTRIBUTION, f"tension distribution "
                       f"{out.status.name} (the feed-forward alone): {out.message}")  # fmt: skip
        elif d.saturated_for > self.config.max_saturation_time:
            self.fault(
                t,
                FaultKind.TENSION_DISTRIBUTION,
                f"feedback wrench saturated for {d.saturated_for:.2f} s "
                f"(> max_saturation_time {self.config.max_saturation_time:g} s; "
                f"the cables gave {d.saturation:.0%} of it last)",
            )

    def _over_speed(self, t: float, speed: float, limit: float) -> bool:
        return self._speed_over.held(t, speed > limit)
