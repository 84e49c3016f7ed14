"""One control cycle, composed of parts with one job each (``docs/architecture.md``).

``Controller.update(t, feedback)``: commands → estimate (FK) → supervise → trajectory (ruckig)
→ pose control (PID + feedforward of gravity, platform inertia and the known external wrench)
→ TDA (the configured method; the Picard et al. 2020 Fig. 3 scheme) → winch torques
(``(r/G) t`` + friction and rotor-inertia feedforward, limits). The drives' I/O — read before,
write after — is the manager's (``manager.py``); the controller only asks the drives to change
their lifecycle (``DrivePort``). Every output lands in ``data`` (``ControlData``), which is
what outside readers read. Commands arrive at the desk (``desk.py``: checked on the way in,
acted on at the start of a cycle); the start-up's fixed point is ``initialise.py``; the faults
are the supervisor's (``supervisor.py``); the state is the state machine's alone
(``state_machine.py``), which the three ask. Each stage gets its inputs and outputs in its
call, as the bundles of ``cycle_io.py``, built here once.
"""

from __future__ import annotations

import math
import time

import numpy as np

from cdprctl.control.command_types import Command
from cdprctl.control.cycle.cable_space import CableSpace
from cdprctl.control.cycle.cycle_io import CycleIO, reference_args
from cdprctl.control.cycle.distribution import Distribution
from cdprctl.control.cycle.estimator import Estimator
from cdprctl.control.cycle.gripper_control import GripperControl
from cdprctl.control.cycle.observer import WrenchObserver
from cdprctl.control.cycle.reference_pose import ReferencePose, WorkingPose
from cdprctl.control.cycle.tension_source import LoadCellCheck
from cdprctl.control.cycle.torques import WinchTorques
from cdprctl.control.cycle.wrench import PoseController
from cdprctl.control.data import ControlData
from cdprctl.control.intake.desk import CommandDesk, DeskPorts, Verdict
from cdprctl.control.intake.jog import Jog
from cdprctl.control.intake.path_follower import PathFollower
from cdprctl.control.states import (
    ACTIVE_STATES,
    DISABLING,
    ENABLED,
    HEALTHY_STATES,
    MOVING,
    STOPPING,
    FaultKind,
)
from cdprctl.control.supervision.clearance_watch import ClearanceWatch
from cdprctl.control.supervision.drive_port import DrivePort
from cdprctl.control.supervision.state_machine import StateMachine
from cdprctl.control.supervision.supervisor import Supervisor
from cdprctl.core.numerics import count_kernel, min2
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.gripper_mechanics import GripperSet
from cdprctl.geometry.interference import Interference, interference_kernel
from cdprctl.model.robot import RobotModel
from cdprctl.motion.limits import SoftLimits
from cdprctl.motion.trajectory import Trajectory
from cdprctl.tda import TDAOptions, tda_options_of
from drivers.vocabulary import WinchStates

# the states in which the external wrench is observed (the drives apply what is computed)
LOAD_CELL = FaultKind.LOAD_CELL  # bound once: states.py says why
OBSERVED_STATES = (ENABLED, MOVING, DISABLING, STOPPING)  # a tuple: states.py says why


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
        self.reference = ReferencePose(model)
        self.at: WorkingPose = self.reference if model.drives.holds_lengths else e
        # the bundles the stages read and write, named in each call (cycle_io.py)
        self.io = CycleIO.build(
            reference_args(tr.position, tr.velocity, tr.acceleration), e, self.at, d
        )
        self.pose = PoseController(model)
        self.winches = WinchTorques(model)
        self.distribution = Distribution(model, d, GripperSet(model), tda or tda_options_of(model))
        self.ext_wrench = np.array(c.external_wrench, dtype=float)  # N, N·m, known
        d.ext_total[:] = self.ext_wrench
        self.observer = WrenchObserver(model, d, self.winches)
        self.cable_space = CableSpace(model, d)
        self.load_cells = LoadCellCheck(model, self.winches)  # tension_source.py
        self._rotor_term = np.zeros(model.n_cables)  # N·m, for its check
        self.grippers = GripperControl(model, d, gs, e, self.at, self.winches,
                                       self.distribution, self.ext_wrench, tr)  # fmt: skip
        # position mode: the cables' internal tension error is supervised, per cable (N)
        tension_limits = (
            c.max_tension_disagreement * (model.tension_max - model.tension_min)
            if model.drives.holds_lengths
            else None
        )
        # position mode: a drive sitting at its torque limit is a load beyond the cables
        torque_limits = self.winches.limit.copy() if model.drives.holds_lengths else None
        # the one owner of data.state: the desk, the supervisor and the start-up ask it
        self.machine = StateMachine(d)
        # the cables' clearance at the estimated pose (data.interference), watched
        # targets set by commands (submit, outside the loop) keep the soft limits
        self.limits = SoftLimits(model, self.ext_wrench)
        self.interference = d.interference = Interference(model)
        watch = ClearanceWatch(self.interference, self.limits.clearance.home_distance)
        self._clearance = self.interference.arrays if watch.active else None
        self.supervisor = Supervisor(c, d, drives, tension_limits, torque_limits, model.safety,
                                     self.machine, watch)  # fmt: skip
        self.jog = Jog(model, d)
        self.path = PathFollower(model, d)
        # Tensions used for the estimator's stretch correction: the feed-forward ones (gravity,
        # the known external wrench and the trajectory's inertial load, distributed like the
        # commanded ones) at the estimated pose. The commanded tensions, PD feedback included,
        # would close an algebraic loop (tension → stretch → pose estimate → PD → tension) of
        # gain ~1 on the window-cleaning robot: the estimate diverged by 9 mm within 0.13 s of
        # enabling; static tensions alone leave out the inertial load, and the ill-conditioned
        # y direction turned its 0.2 mm of stretch into 6 mm of estimate (lock-step, measured).
        self._ff_wrench = np.zeros(6)
        self.stretch_every = max(1, round(self.STRETCH_PERIOD / self.period))
        self._stretch_due = True  # this cycle refreshes the stretch tensions (torque mode)
        # s as a float: the ns counter's ints are past the small ones Python keeps, a block
        # each (the cycle allocates nothing: tests/control/cycle/test_allocations.py)
        self._clock = time.perf_counter
        self._last_t = -math.inf  # s, the last cycle's time
        # s: position mode, the most the reference moves on across a stall of the loop
        self._extrapolation = model.drives.target_extrapolation
        self.desk = CommandDesk(DeskPorts(
            model, d, self.machine, drives, tr, self.limits, self.jog, self.path, self.supervisor,
            self.distribution, self.grippers, self.restart, self.pose6,
        ))  # fmt: skip
        d.gains = {
            "force_feedback": self.cable_space.iff,
            "disturbance_bandwidth": self.cable_space.disturbance_bandwidth,
            "pose_bandwidth": self.pose.bandwidth.tolist(),
        }
        # what outside readers see, bound once
        d.position, d.rotation = e.position, e.rotation
        d.velocity, d.omega = e.velocity, e.omega
        d.reference, d.target = tr.position, tr.target

    def submit(self, cmd: Command) -> Verdict:
        """``CommandDesk.submit``: queue a command for the next cycle, or refuse it (why)."""
        return self.desk.submit(cmd)

    # -- the cycle ---------------------------------------------------------------------------------
    def update(self, t: float, st: WinchStates) -> None:
        """One cycle at time ``t`` (s) from the drives' feedback ``st``, stage by stage, each
        stage's inputs and outputs named in its call (the bundles of ``cycle_io.py``); every
        output into ``data`` (phases 1-5 of ``PHASES`` timed)."""
        clock, d, io, e, tr = self._clock, self.data, self.io, self.estimator, self.trajectory
        ph = d.phase_us
        t1 = clock()
        gap = self._step_time(t)
        if not self.grippers.n:  # the known external wrench, whoever set it, from now on
            np.copyto(d.ext_total, self.ext_wrench)  # copyto: a slice would build a view
        np.copyto(d.motor_position, st.position)
        self.desk.handle(t)  # the commands: state requests, targets (desk.py)
        # 1. estimate ← feedback, the cables stretched by the tensions this mode assumes
        self._stretch_tensions(st)
        fk = e.update(st.stamp, st.position, d.stretch_tensions, st.velocity, st.feedback_age)
        if self._clearance is not None:  # → data.interference, at the estimate's cables
            interference_kernel(e.kin.arrays, e.position, e.rotation, self._clearance)
        if d.state in OBSERVED_STATES:  # estimate, feedback → data.ext_estimate
            self.observer.update(t, st.torque, st.velocity, tr.acceleration, io.estimate, e.kin,
                                 st.tension)  # fmt: skip
            self._check_cells(t, st)
        if self.grippers.n:
            self.grippers.update(st, sense=True)  # ext_total: + the jaws' weight
        t2 = clock()
        ph[1] = (t2 - t1) * 1e6
        # 2. reference ← the trajectory and its sources, after the supervisor's checks
        last = e.last_fk
        self.jog.update(t, tr)
        self.path.update(t, tr)
        self.supervisor.supervise(
            t,
            fk.status,
            last.residual if last is not None else 0.0,
            math.hypot(e.velocity.item(0), e.velocity.item(1), e.velocity.item(2)),
            tr.finished and not self.path.holds_motion,
            e.position,
        )
        self._brake_if_asked()
        self.desk.motion_ended(tr.finished and not self.path.holds_motion)
        tr.update(self._reference_step(gap))  # → io.reference
        if self.cable_space.enabled:  # position mode: the working pose, at the reference
            self.reference.update(io.reference, e)  # → io.working
        t3 = clock()
        ph[2] = (t3 - t2) * 1e6
        # 3. wrench ← reference, working pose, the known external wrench
        active = d.state in ACTIVE_STATES
        if active:  # anti-windup: the integral holds while the feedback is saturated
            integrate = d.state in HEALTHY_STATES and d.saturation >= 1.0
            self.pose.update(io.reference, io.working, d.ext_total, integrate, d.dt, io.wrench)
        t4 = clock()
        ph[3] = (t4 - t3) * 1e6
        # 4. tensions ← wrench at the working pose (data.wrench → data.tensions)
        if active:
            out = self.distribution.distribute(self.at)
            self.supervisor.distribution(t, self.distribution.bad_cycles, out)
            self._brake_if_asked()
        t5 = clock()
        ph[4] = (t5 - t4) * 1e6
        # 5. torques, targets ← tensions
        self.winches.update(d.tensions, self.at.kin.WT, tr.acceleration, st.velocity, active,
                            d.torques)  # fmt: skip
        if self.cable_space.enabled:
            ref = self.reference  # → data.motor_target
            self.cable_space.targets(active, st.position, ref.reference_kin.length, ref.k,
                                     self.estimator.winding)  # fmt: skip
        ph[5] = (clock() - t5) * 1e6

    def _step_time(self, t: float) -> float:
        """``data.dt``, ``time``, ``cycle`` for a cycle at ``t`` (s); the gap (s) since the
        last. The real elapsed time: after a late or missed period the integral, the
        trajectory, the tension rate limit, the ramps and the saturation time step by what
        passed."""
        d = self.data
        gap = t - self._last_t
        d.dt = gap if 0.0 < gap < self.MAX_STEP else self.period
        self._last_t = t
        d.time = t
        self._stretch_due = count_kernel(d.cycles, self.stretch_every)  # a bool: no int
        return gap

    def _stretch_tensions(self, st: WinchStates) -> None:
        """``data.stretch_tensions`` for the estimate. Position mode, the drives on: the
        commanded ones (the drives hold the lengths they stretch; no pose feedback there, so no
        algebraic loop), and the cables measured (``CableSpace``: measured tensions, tension
        error, the external wrench fed forward, the force feedback's give). Else every
        ``stretch_every`` cycles the feed-forward ones (``refresh_stretch_tensions``)."""
        d, cs = self.data, self.cable_space
        if cs.enabled and d.state in OBSERVED_STATES:
            np.copyto(d.stretch_tensions, d.tensions)
            cs.measure(st.torque, st.velocity, st.sampled_at, self.distribution.current.ns.N,
                       self.winches.terms, st.tension)  # fmt: skip
            cs.estimate_disturbance(
                self.at.kin.W,
                d.state is not STOPPING
                and d.saturation >= 1.0
                and self.distribution.bad_cycles == 0,
                d.ext_estimate,
            )
            d.ext_total += d.ext_estimate  # fed forward: the pose law and the TDA see it
            cs.force_feedback(self.reference.k, stopping=d.state is STOPPING)
        elif self._stretch_due:
            self.refresh_stretch_tensions()

    def _check_cells(self, t: float, st: WinchStates) -> None:
        """The load cells' supervision (``LoadCellCheck``): a fault that names the cell."""
        if self.load_cells.cells:
            accel = self._rotor_term  # N·m: the torques' rotor-inertia feed-forward
            self.winches.rotor_term(self.at.kin.WT, self.trajectory.acceleration, accel)
            why = self.load_cells.check(t, st.torque, st.velocity, accel, st.tension)
            if why:
                self.supervisor.fault(t, LOAD_CELL, why)
                self._brake_if_asked()

    def _reference_step(self, gap: float) -> float:
        """s the reference moves on this cycle, ``gap`` s after the last. Position mode: as
        long as the drives went on at their targets' rate, then held; it waits out the rest of
        a longer stall (by all of it, the next targets stepped ahead of the held drives: a
        following-error fault, 78 ms at 0.2 m/s on rowc). Torque mode: ``data.dt``."""
        if self.cable_space.enabled and 0.0 < gap < math.inf:
            return min2(gap, self._extrapolation)
        return self.data.dt

    # s: a longer gap between cycles (the first one, or after the loop stood still) steps by a
    # period: what happened meanwhile is not the controller's to integrate
    MAX_STEP = 0.1

    def internal_error(self, t: float, exc: Exception) -> None:
        """The cycle failed: hold the last feasible tensions and stop the controlled way."""
        d = self.data
        d.torques[:] = self.winches.r * d.hold_tensions
        self.supervisor.fault(
            t, FaultKind.INTERNAL, f"internal error: {type(exc).__name__}: {exc}"
        )
        self._brake_if_asked()

    def _brake_if_asked(self) -> None:
        """A fault's controlled stop: the reference braked to rest where it is, at once."""
        if self.supervisor.take_stop():
            self.trajectory.stop_here()

    def restart(self) -> None:
        """Enable (the desk): every stage starts afresh from the holding pose — the reference
        there, the holding tensions commanded, the integrals, the observer, the measured
        tensions, the load cells' checks and the saturation of before forgotten, the grippers
        holding their travel, no stop since."""
        self.trajectory.reset(self.pose6())
        self.reference.restart()
        self.distribution.restart()
        self.pose.reset()
        self.observer.reset(self.io.estimate)
        self.cable_space.start_measuring()
        self.load_cells.reset()
        self.grippers.hold()
        self.supervisor.restart()

    def start_from(self, motor_position: FloatArray) -> None:
        """The start-up's first guess (``initialise.py``): the motors at ``motor_position``
        (rad), the cables stretched by the minimum tensions."""
        np.copyto(self.data.motor_position, motor_position)
        self.data.stretch_tensions[:] = self.model.tension_min

    def refresh_stretch_tensions(self) -> None:
        """The feed-forward tensions for the estimator's stretch (``Distribution.stretch``)."""
        e, tr, pf, ff = self.estimator, self.trajectory, self.model.platform, self._ff_wrench
        ff[:] = self.pose.gravity_hold(e.rotation, self.data.ext_total)
        if self.data.state in OBSERVED_STATES:  # the trajectory's acceleration is applied
            ff[:3] += pf.mass * tr.acceleration[:3]
            ff[3:] += e.rotation @ pf.inertia @ e.rotation.T @ tr.acceleration[3:]
        self.distribution.stretch(ff, self.at)

    def pose6(self) -> FloatArray:
        """The estimated pose as trajectory coordinates."""
        return self.trajectory.coordinates(self.estimator.position, self.estimator.rotation)
