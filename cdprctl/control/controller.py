"""One control cycle and the supervisor's state machine.

Per cycle (``Controller.step``): read (drain the drives' feedback) → estimate (FK) → trajectory
(ruckig) → control (PD on the pose error + feedforward of gravity, platform inertia and the known
external wrench) → TDA (the configured method; the Picard et al. 2020 Fig. 3 scheme) → winch
torques (``(r/G) t`` + friction and rotor-inertia feedforward, limits) → write (RPDOs, SYNC).
Nothing in it raises, logs or allocates much: events go to a bounded deque that the daemon
drains outside the loop; commands arrive through a bounded mailbox.

Supervisor states::

    INIT ─startup()→ READY ─enable→ ENABLING ─drives on→ ENABLED ⇄ MOVING (move / finished)
    ENABLED/MOVING ─stop→ ENABLED (decelerated, holding)    ─disable→ DISABLING → READY
    any ─fault→ STOPPING (hold the pose with feasible tensions, stop_duration) → FAULT
    FAULT ─reset→ READY (drive faults reset, drives disabled)

A driver fault skips STOPPING: the drives are not to be trusted, their brakes close.
"""

from __future__ import annotations

import collections
import dataclasses
import enum
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from cdprctl.control.estimator import Estimator
from cdprctl.control.grasp import GraspSensor
from cdprctl.control.grip_range import travel_range
from cdprctl.control.pd_kernel import pd_wrench_kernel
from cdprctl.control.trajectory import Trajectory
from cdprctl.control.warm_up import warm_up
from cdprctl.control.winch_torque import FRICTION_SMOOTHING, winch_torque_kernel
from cdprctl.forward_kinematics import FKStatus
from cdprctl.gripper import GraspState, GripperSet
from cdprctl.model.robot import RobotModel
from cdprctl.rotation import FloatArray, log_so3
from cdprctl.tda import (
    ImposedQuantity,
    Imposition,
    TDAMethod,
    TDAOptions,
    TDAStatus,
    TensionDistributor,
)
from drivers.base import Lifecycle, WinchDriver


class State(enum.Enum):
    INIT = "init"
    READY = "ready"  # drives inactive (brakes), feedback live, pose estimated
    ENABLING = "enabling"
    ENABLED = "enabled"  # holding the pose
    MOVING = "moving"
    DISABLING = "disabling"
    STOPPING = "stopping"  # a fault: holding, then disabling
    FAULT = "fault"


@dataclass
class Command:
    kind: str  # enable | disable | stop | reset | move | set_tda | gripper
    pose: FloatArray | None = None  # move: x, y, z (m), roll, pitch, yaw (rad)
    speed: float = 1.0  # move: fraction of the velocity limits
    accel: float = 1.0  # move: fraction of the acceleration limits
    tda: TDAOptions | None = None
    gripper: int = 0  # gripper: index in [[grippers]]
    grip: str = ""  # gripper: travel | force | release
    value: float = 0.0  # gripper: travel (m) or squeeze force (N)


PHASES = ("read", "estimate", "trajectory", "control", "tda", "torques", "write")


def tda_options_of(model: RobotModel) -> TDAOptions:
    c = model.control
    return TDAOptions(
        method=TDAMethod(c.tda_method),
        nu=c.tda_nu,
        direction=c.tda_direction,
        impositions=tuple(
            Imposition(i.cable, ImposedQuantity(i.quantity), i.value) for i in c.impositions
        ),
        max_tension_rate=c.max_tension_rate,
        period=c.period,
    )


class Controller:
    def __init__(self, model: RobotModel, driver: WinchDriver, tda: TDAOptions | None = None):
        c = model.control
        self.model = model
        self.driver = driver
        self.period = c.period
        self.state = State.INIT
        self.estimator = Estimator(model)
        self.trajectory = Trajectory(model, self.period)
        self.tda = TensionDistributor(model, tda or tda_options_of(model))
        m = model.n_cables
        self.r = self.estimator.drum_ratio  # m/rad
        w = [x.winch for x in model.cables]
        self.rotor_inertia = np.array([x.rotor_inertia for x in w])
        self.viscous = np.array([x.viscous_friction for x in w])
        self.coulomb = np.array([x.coulomb_friction for x in w])
        self.torque_limit = np.array([x.torque_limit for x in w])
        self.t_min = model.tension_min + c.tension_margin
        self.t_max = model.tension_max - c.tension_margin
        bw = c.axis_bandwidth if c.axis_bandwidth is not None else (c.bandwidth,) * 6
        wn = 2.0 * math.pi * np.array(bw, dtype=float)  # rad/s per axis
        # PID by pole placement, a triple pole at −ω_n (s + ω)³: kp = 3ω², kd = 3ω, ki = ω³
        # (accelerations per m, per m/s, per m·s). The integral removes the PD's compliance
        # to a steady force (the water jet): what remains is the cables' own elasticity, the
        # stiffness the SOTDA acts on (Picard et al. 2020). damping_ratio scales kd. Per axis
        # (x, y, z, roll, pitch, yaw) when [control] axis_bandwidth is given.
        self.kp = 3.0 * wn * wn
        self.kd = 3.0 * c.damping_ratio * wn
        self.ki = wn**3
        self.integral = np.zeros(6)  # m·s, rad·s
        self.integral_limit = 10.0 / self.ki  # the integral term stays within 10 m/s² (rad/s²)
        self.ext_wrench = np.array(c.external_wrench, dtype=float)
        # The reconfigurable end-effector (Sensors 2019 §2.4): the jaws' weight wrench joins
        # the known external wrench (eq. (46)), updated with the orientation every cycle; the
        # TDA works on the springs' tensions τ_A (jB's load added back, eq. (26)).
        self.grippers = GripperSet(model)
        self.jb_load = np.zeros(self.grippers.n)  # N, what each jB carries
        self.grasp = GraspSensor(self.grippers, self.period)
        self.grip_target = np.full(self.grippers.n, math.nan)  # m, commanded travel
        self.grip_imposed = np.full(self.grippers.n, math.nan)  # m, ramping towards it
        # without grippers the known external wrench is all: the same array, whoever sets it
        self._ext_total = self.ext_wrench.copy() if self.grippers.n else self.ext_wrench
        self._spring_prev = np.zeros(m)
        self._range_tda: TensionDistributor | None = None
        # a switch of distribution blends from the old one (see _blend)
        self._old_tda: TensionDistributor | None = None
        self._old_static: TensionDistributor | None = None
        self._blend_start = -math.inf
        self._blend_old = np.zeros(m)
        self.tensions = np.zeros(m)  # N, commanded
        # Tensions used for the estimator's stretch correction: the feed-forward ones (gravity,
        # the known external wrench and the trajectory's inertial load, distributed like the
        # commanded ones) at the estimated pose. The commanded tensions, PD feedback included,
        # would close an algebraic loop (tension → stretch → pose estimate → PD → tension) of
        # gain ~1 on the window-cleaning robot: the estimate diverged by 9 mm within 0.13 s of
        # enabling; static tensions alone leave out the inertial load, and the ill-conditioned
        # y direction turned its 0.2 mm of stretch into 6 mm of estimate (lock-step, measured).
        self.stretch_tensions = np.zeros(m)
        self._last_stretch = np.full(m, np.inf)
        self._ff_wrench = np.zeros(6)
        self._static_tda = TensionDistributor(model, tda or tda_options_of(model))
        self.hold_tensions = np.zeros(m)  # N, the last feasible distribution
        self.torques = np.zeros(m)  # N·m, commanded
        self.wrench = np.zeros(6)  # what the cables were asked for
        self.tda_status = TDAStatus.OK
        self.pose_error = np.zeros(6)  # m, rad: desired − estimated
        self.fault_reason = ""
        self.cycle = 0
        self.time = 0.0
        self.events: collections.deque[tuple[float, str]] = collections.deque(maxlen=256)
        self.mailbox: collections.deque[Command] = collections.deque(maxlen=64)
        self.phase_us = np.zeros(len(PHASES))  # last cycle, µs
        self._t_state = 0.0
        self._stop_until = 0.0
        self._after_stop = State.FAULT
        self._tda_bad = 0
        self._clock_ns = time.perf_counter_ns
        self._stretch_every = max(1, round(self.STRETCH_PERIOD / self.period))
        self._over_speed_since = math.inf
        # contiguous float64 copies for the compiled PID kernel
        self._R_home = np.ascontiguousarray(model.home.rotation, dtype=float)
        self._inertia = np.ascontiguousarray(model.platform.inertia, dtype=float)
        self._com = np.ascontiguousarray(model.platform.com, dtype=float)
        self._gravity = np.ascontiguousarray(model.gravity, dtype=float)
        self._Rd = np.zeros((3, 3))
        self._E = np.zeros((3, 3))

    # -- outside the loop ------------------------------------------------------------------------
    def startup(self, timeout: float = 5.0) -> None:
        """Configure the drives, read them, estimate the pose from the home pose as a start,
        check it can be held (a TDA under gravity) → READY. Raises on failure."""
        d = self.driver
        warm_up(self)  # every kernel compiled before the drives start (cdprctl/control/warm_up.py)
        d.configure(timeout)
        now = d.clock()
        st = d.read(now)
        self.estimator.reset(self.model.home.position, self.model.home.rotation)
        # The stretch depends on the tensions, which depend on the pose: a fixed point,
        # from the minimum tensions (soft cables, e.g. the Sensors 2019 springs, need a few
        # iterations; steel ones one or two).
        self.stretch_tensions[:] = self.model.tension_min
        for _ in range(100):
            fk = self.estimator.update(now, st.position, self.stretch_tensions)
            if fk.status in (FKStatus.DEGENERATE, FKStatus.BAD_INPUT):
                raise RuntimeError(f"start-up: forward kinematics failed ({fk.status.name})")
            self._update_grippers(st, sense=False)
            out = self._solve(self.tda, self._gravity_hold(), None)
            # on the way, a pose that cannot be held gives its least-violating tensions: the
            # fixed point goes on from them (from the minimum tensions, with the pose from six
            # cables, the first poses of the springy Sensors 2019 robot are far off)
            self._total(out.tensions, self.hold_tensions)
            self._total(out.tensions, self.stretch_tensions)
            if out.ok and self.cycle % self._stretch_every == 0:
                self._refresh_stretch_tensions()
            change = float(np.max(np.abs(self.stretch_tensions - self._last_stretch)))
            self._last_stretch[:] = self.stretch_tensions
            if change < 1e-3:
                break
        else:
            raise RuntimeError("start-up: pose and tensions did not settle in 100 iterations")
        if not out.ok:
            p = self.estimator.position
            raise RuntimeError(
                f"start-up: the estimated pose [{p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}] m "
                f"cannot be held ({out.status.name}: {out.message})"
            )
        if fk.residual > self.model.control.max_fk_residual:
            raise RuntimeError(
                f"start-up: the encoders disagree with every pose "
                f"({fk.status.name}, residual {fk.residual:.3g} m)"
            )
        self.tensions[:] = self.hold_tensions
        self.estimator.velocity[:] = 0.0
        self.estimator.omega[:] = 0.0
        self.trajectory.reset(self._pose6())
        self._set_state(State.READY, now, "drives inactive, feedback live, pose estimated")

    def submit(self, cmd: Command) -> bool:
        """Queue a command for the next cycle; False when the mailbox is full."""
        if len(self.mailbox) >= (self.mailbox.maxlen or 0):
            return False
        self.mailbox.append(cmd)
        return True

    # -- the cycle ---------------------------------------------------------------------------------
    def step(self, t: float) -> None:
        """One control cycle at time ``t`` (s). Never raises."""
        clock = self._clock_ns
        ph = self.phase_us
        try:
            t0 = clock()
            st = self.driver.read(t)
            t1 = clock()
            ph[0] = (t1 - t0) / 1e3
            self.time = t
            self.cycle += 1
            self._handle_commands(t)
            if self.cycle % self._stretch_every == 0:
                self._refresh_stretch_tensions()
            fk = self.estimator.update(
                st.stamp, st.position, self.stretch_tensions, st.velocity, st.feedback_age
            )
            if self.grippers.n:
                self._update_grippers(st, sense=True)
            t2 = clock()
            ph[1] = (t2 - t1) / 1e3
            self._supervise(t, fk.status)
            self.trajectory.update()
            t3 = clock()
            ph[2] = (t3 - t2) / 1e3
            active = self.state in (State.ENABLING, State.ENABLED, State.MOVING, State.STOPPING)
            if active:
                self._control()
            t4 = clock()
            ph[3] = (t4 - t3) / 1e3
            if active:
                self._distribute(t)
            t5 = clock()
            ph[4] = (t5 - t4) / 1e3
            self._winch_torques(st.velocity, active)
            t6 = clock()
            ph[5] = (t6 - t5) / 1e3
            self.driver.write(t, self.torques)
            ph[6] = (clock() - t6) / 1e3
        except Exception as exc:
            self.torques[:] = self.r * self.hold_tensions
            self._fault(t, f"internal error: {type(exc).__name__}: {exc}", hold=True)

    # The feed-forward load is jerk-limited and changes slowly: the stretch tensions are
    # refreshed every 8 ms (4 cycles at 500 Hz), which halves the estimate phase's cost.
    STRETCH_PERIOD = 0.008  # s

    def _refresh_stretch_tensions(self) -> None:
        e, tr, pf = self.estimator, self.trajectory, self.model.platform
        ff = self._ff_wrench
        ff[:] = self._gravity_hold()
        if self.state in (State.ENABLED, State.MOVING, State.STOPPING):
            ff[:3] += pf.mass * tr.acceleration[:3]
            ff[3:] += e.rotation @ pf.inertia @ e.rotation.T @ tr.acceleration[3:]
        out = self._solve(self._static_tda, ff, None)
        if out.ok:
            self._total(out.tensions, self.stretch_tensions)
            self._blend(self._old_static, ff, None, self.stretch_tensions)

    def _solve(self, tda: TensionDistributor, wrench: FloatArray, t_prev: FloatArray | None) -> Any:
        """The TDA at the estimated pose, on the springs' tensions when there are grippers."""
        e, gs = self.estimator, self.grippers
        if gs.n:
            wrench = gs.spring_wrench(e.kin.W, wrench, self.jb_load)
            if t_prev is not None:
                tp = self._spring_prev
                tp[:] = t_prev
                tp[gs.cables] -= self.jb_load
                t_prev = tp
        return tda.solve(
            e.kin.W, wrench, self.t_min, self.t_max, k=e.k, kin=e.kin, t_prev=t_prev
        )

    def _total(self, spring: FloatArray, out: FloatArray) -> None:
        """Cable tensions (N) into ``out`` from the springs' ``spring``: ``τ = τ_A + τ_B``."""
        out[:] = spring
        if self.grippers.n:
            out[self.grippers.cables] += self.jb_load

    def _update_grippers(self, st: Any, sense: bool) -> None:
        """The jaws' weight wrench and jB's load at the estimated orientation; the grasp state
        from the drives' torque and position; the imposed travels ramped to their targets."""
        gs, e = self.grippers, self.estimator
        R = e.rotation
        self._ext_total[:] = self.ext_wrench + gs.weight_wrench(R)
        f_par = gs.parallel_load(R)
        if sense:
            c = gs.cables
            th, w = st.position[c], st.velocity[c]
            l0 = e.l_home[c] - self.r[c] * th
            friction = self.viscous[c] * w + self.coulomb[c] * np.tanh(w / FRICTION_SMOOTHING)
            torque = st.torque[c] - friction
            self.grasp.update(torque / self.r[c], e.kin.length[c] - l0, f_par)
        # jB's load as the open model has it: the sensed squeeze is not fed back here (a loop
        # through the sensor's own estimate drifted into an infeasible wrench in lock-step);
        # a squeeze command puts the force into the imposition instead (_gripper_command)
        self.jb_load[:] = f_par
        self._ramp_grip_impositions()

    # -- phases ------------------------------------------------------------------------------------
    def _pose6(self) -> FloatArray:
        e = self.estimator
        return np.concatenate([e.position, log_so3(e.rotation @ self.model.home.rotation.T)])

    def _gravity_hold(self) -> FloatArray:
        return -(self.model.gravity_wrench(self.estimator.rotation) + self._ext_total)

    def _control(self) -> None:
        """Cable wrench: ``M (a_d + Kp e + Ki ∫e + Kd ė) − w_g − w_e`` (PID + feedforward;
        the compiled kernel of ``pd_kernel.py``)."""
        e, tr, pf = self.estimator, self.trajectory, self.model.platform
        pd_wrench_kernel(
            tr.position,
            tr.velocity,
            tr.acceleration,
            e.position,
            e.rotation,
            e.velocity,
            e.omega,
            self._R_home,
            self.kp,
            self.kd,
            self.ki,
            self.integral,
            self.integral_limit,
            self.state is State.ENABLED or self.state is State.MOVING,
            self.period,
            pf.mass,
            self._inertia,
            self._com,
            self._gravity,
            self._ext_total,
            self._Rd,
            self._E,
            self.pose_error,
            self.wrench,
        )

    def _distribute(self, t: float) -> None:
        # while a switch blends, the blend limits the tension rate: a rate limit on either
        # side would hold the commanded tensions back from the stretch estimate's (which has
        # none) and the pose estimate would see the difference as an encoder fault
        blending = self._old_tda is not None
        out = self._solve(self.tda, self.wrench, None if blending else self.tensions)
        self.tda_status = out.status
        if out.status is TDAStatus.OK or out.status is TDAStatus.IMPOSITION_INFEASIBLE:
            self._total(out.tensions, self.tensions)
            self._blend(self._old_tda, self.wrench, None, self.tensions)
            self.hold_tensions[:] = self.tensions
            self._tda_bad = 0
        else:  # infeasible wrench: hold the last feasible tensions, never leave the limits
            self.tensions[:] = self.hold_tensions
            self._tda_bad += 1
            if self._tda_bad >= 3 and self.state is not State.STOPPING:
                self._fault(t, f"tension distribution {out.status.name}: {out.message}", hold=True)

    # A new distribution takes over in this time: both hold the wrench, so every blend does,
    # inside the limits (a convex set). A step from the barycenter to the minimum of energy
    # moved seed000's soft cables by 10-20 N, 1-2 cm of stretch the pose estimate took for an
    # encoder fault at once (lock-step, tests/test_closed_loop_seed000.py).
    BLEND_TIME = 1.0  # s

    def _blend(
        self,
        old: TensionDistributor | None,
        wrench: FloatArray,
        t_prev: FloatArray | None,
        tensions: FloatArray,
    ) -> None:
        """``tensions`` (the new distribution's, N) ← a blend with the old distribution's
        while a switch is under way; unchanged when the old one has nothing feasible."""
        if old is None:
            return
        s = (self.time - self._blend_start) / self.BLEND_TIME
        if s >= 1.0:
            self._old_tda = self._old_static = None
            return
        out = self._solve(old, wrench, t_prev)
        if out.status is TDAStatus.OK or out.status is TDAStatus.IMPOSITION_INFEASIBLE:
            old_total = self._blend_old
            self._total(out.tensions, old_total)
            tensions *= s
            tensions += (1.0 - s) * old_total

    def _winch_torques(self, motor_velocity: FloatArray, active: bool) -> None:
        """``τ = (r/G) t + b θ̇ + τ_c tanh(θ̇/ω_ε) + J θ̈_d``, clamped (θ > 0 winds in)."""
        if not active:
            self.torques[:] = 0.0
            return
        winch_torque_kernel(
            self.tensions,
            self.r,
            self.viscous,
            self.coulomb,
            self.rotor_inertia,
            self.estimator.kin.WT,
            self.trajectory.acceleration,
            motor_velocity,
            self.model.control.friction_compensation,
            self.torque_limit,
            self.torques,
        )

    # -- supervisor ------------------------------------------------------------------------------
    def _set_state(self, s: State, t: float, why: str) -> None:
        if s is not self.state:
            self.events.append((t, f"state {self.state.value} -> {s.value}: {why}"))
        self.state = s
        self._t_state = t

    def _fault(self, t: float, reason: str, hold: bool) -> None:
        if self.state in (State.FAULT, State.STOPPING):
            return
        self.fault_reason = reason
        self.events.append((t, f"FAULT: {reason}"))
        if hold and self.driver.lifecycle is Lifecycle.ACTIVE:
            self.trajectory.stop_here()
            self._stop_until = t + self.model.control.stop_duration
            self._set_state(State.STOPPING, t, "controlled stop, holding the pose")
        else:
            self.driver.begin_deactivate()
            self._set_state(State.FAULT, t, "drives disabled, brakes closed")

    def _supervise(self, t: float, fk_status: FKStatus) -> None:
        c = self.model.control
        d = self.driver
        if d.lifecycle is Lifecycle.ERROR and self.state is not State.FAULT:
            if self.state is State.STOPPING:  # the drives failed during the controlled stop
                self.events.append((t, f"FAULT during the stop: drives: {d.error}"))
                self.driver.begin_deactivate()
                self._set_state(State.FAULT, t, "drives disabled, brakes closed")
            else:
                self._fault(t, f"drives: {d.error}", hold=False)
            return
        if self.state is State.ENABLING:
            if d.lifecycle is Lifecycle.ACTIVE:
                self._set_state(State.ENABLED, t, "drives enabled, holding the pose")
            elif t - self._t_state > 2.0:
                self._fault(t, "drives not enabled within 2 s", hold=False)
            return
        if self.state is State.DISABLING:
            self.driver.begin_deactivate()
            self._set_state(State.READY, t, "drives disabled, brakes closed")
            return
        if self.state is State.STOPPING:
            if t >= self._stop_until:
                self.driver.begin_deactivate()
                self._set_state(State.FAULT, t, "stopped; drives disabled, brakes closed")
            return
        if self.state not in (State.ENABLED, State.MOVING):
            return
        if self.state is State.MOVING and self.trajectory.finished:
            self._set_state(State.ENABLED, t, "target reached")
        e = self.estimator
        # plain floats: five numpy reductions here cost ~15 µs a cycle
        age = max(d.states.feedback_age.tolist())
        pe = self.pose_error.tolist()
        position_error = math.hypot(pe[0], pe[1], pe[2])
        angle_error = math.hypot(pe[3], pe[4], pe[5])
        speed = math.hypot(*e.velocity.tolist())
        fk = e.last_fk
        if fk_status in (FKStatus.DEGENERATE, FKStatus.BAD_INPUT):
            self._fault(t, f"forward kinematics {fk_status.name}", hold=True)
        elif fk is not None and fk.residual > self.model.control.max_fk_residual:
            self._fault(
                t,
                f"the encoders disagree with every pose: forward-kinematics residual "
                f"{fk.residual * 1e3:.2f} mm > {self.model.control.max_fk_residual * 1e3:.0f} mm "
                "(an encoder jump, a slipped or broken cable)",
                hold=True,
            )
        elif position_error > c.max_position_error:
            self._fault(
                t,
                f"tracking error {position_error * 1e3:.1f} mm "
                f"> {c.max_position_error * 1e3:.1f} mm",
                hold=True,
            )
        elif angle_error > c.max_angle_error:
            self._fault(
                t,
                f"orientation error {angle_error:.3f} rad > {c.max_angle_error:.3f} rad",
                hold=True,
            )
        elif self._over_speed(t, speed, c.max_speed):
            self._fault(
                t,
                f"platform speed {speed:.2f} m/s > {c.max_speed:.2f} m/s "
                f"for {self.OVER_SPEED_FOR * 1e3:.0f} ms",
                hold=True,
            )
        elif age > c.max_feedback_age:
            self._fault(
                t, f"feedback {age * 1e3:.1f} ms old > {c.max_feedback_age * 1e3:.0f} ms", hold=True
            )

    # The estimated speed must stay over the limit this long: taking over from the brakes moves
    # the drums for a few ms while the cables find their tensions, and in a badly conditioned
    # direction that is a short, false spike of estimated speed (seen across processes after
    # a restart: 2 of 10). A real runaway at the limit goes 30 mm further before the stop.
    OVER_SPEED_FOR = 0.03  # s

    def _over_speed(self, t: float, speed: float, limit: float) -> bool:
        if speed <= limit:
            self._over_speed_since = math.inf
            return False
        self._over_speed_since = min(self._over_speed_since, t)
        return t - self._over_speed_since >= self.OVER_SPEED_FOR - 1e-9

    def _handle_commands(self, t: float) -> None:
        while self.mailbox:
            cmd = self.mailbox.popleft()
            k = cmd.kind
            if (
                k == "enable"
                and self.state is State.READY
                and (self.driver.lifecycle is not Lifecycle.INACTIVE)
            ):  # a drive fault came back after the reset: the supervisor faults next
                self.events.append(
                    (t, f"enable refused: drives {self.driver.lifecycle.value} {self.driver.error}")
                )
            elif k == "enable" and self.state is State.READY:
                self.trajectory.reset(self._pose6())
                self.tensions[:] = self.hold_tensions
                self.integral[:] = 0.0
                self._hold_grippers()
                self.driver.begin_activate()
                self._set_state(State.ENABLING, t, "enabling the drives with holding torques")
            elif k == "move" and (
                cmd.pose is None
                or len(cmd.pose) != 6
                or not np.all(np.isfinite(cmd.pose))
                or not (0.0 < cmd.speed <= 1.0 and 0.0 < cmd.accel <= 1.0)
            ):  # the gateway validates; this is the last guard before the trajectory
                self.events.append((t, "move ignored: pose or speed not finite/in range"))
            elif k == "move" and self.state in (State.ENABLED, State.MOVING):
                assert cmd.pose is not None
                from cdprctl.rotation import rpy_to_matrix

                R = rpy_to_matrix(*cmd.pose[3:])
                x = np.concatenate([cmd.pose[:3], log_so3(R @ self.model.home.rotation.T)])
                self.trajectory.set_target(x, cmd.speed, cmd.accel)
                self._set_state(State.MOVING, t, f"move to {np.round(cmd.pose, 4).tolist()}")
            elif k == "stop" and self.state in (State.ENABLED, State.MOVING):
                self.trajectory.stop_here()
                self._set_state(State.ENABLED, t, "stop: decelerating, then holding")
            elif k == "disable" and self.state in (State.ENABLED, State.MOVING, State.ENABLING):
                self._set_state(State.DISABLING, t, "disable requested")
            elif k == "reset" and self.state is State.FAULT:
                self.driver.begin_recover()
                self.fault_reason = ""
                self.trajectory.reset(self._pose6())
                self._set_state(State.READY, t, "fault reset")
            elif k == "gripper" and self.state in (State.ENABLED, State.MOVING):
                self._gripper_command(t, cmd)
            elif k == "set_tda" and cmd.tda is not None and cmd.tda == self.tda.options:
                # the same options again (an operator's retry, a script): no rebuild, no blend
                self.events.append((t, f"TDA method {cmd.tda.method.value} unchanged"))
            elif k == "set_tda" and cmd.tda is not None:
                try:  # options are validated by whoever sends them; this is the last guard
                    new_tda = TensionDistributor(self.model, cmd.tda)
                    # the stretch estimate assumes the tensions the cables now get
                    new_static = TensionDistributor(self.model, cmd.tda)
                    if self.state in (State.ENABLED, State.MOVING):
                        self._old_tda, self._old_static = self.tda, self._static_tda
                        self._blend_start = t
                    self.tda, self._static_tda = new_tda, new_static
                    self.events.append((t, f"TDA method {cmd.tda.method.value}"))
                except ValueError as exc:
                    self.events.append((t, f"TDA options rejected: {exc}"))
            else:
                self.events.append((t, f"command {k} ignored in state {self.state.value}"))

    # -- the reconfigurable end-effector -------------------------------------------------------
    # The imposed travel moves at this speed: a jump of the imposition is a jump of two cables'
    # tensions, which the jaw and the platform would feel as a blow.
    GRIP_SPEED = 0.02  # m/s

    def gripper_range(self, j: int) -> tuple[float, float]:
        """Travel (m) the redundancy can give gripper ``j`` here, the other grippers held
        where they are imposed (``grip_range.travel_range``). NaN when none."""
        if self._range_tda is None:
            opts = dataclasses.replace(self.tda.options, method=TDAMethod.ENERGY, impositions=())
            self._range_tda = TensionDistributor(self.model, opts)
        e = self.estimator
        return travel_range(
            self.model,
            self._range_tda,
            self.grippers,
            j,
            self.grip_imposed,
            e.kin.W,
            e.rotation,
            self.estimator.k,
            self.ext_wrench,
            self.t_min,
            self.t_max,
        )

    def _gripper_command(self, t: float, cmd: Command) -> None:
        gs, j = self.grippers, cmd.gripper
        if not 0 <= j < gs.n:
            self.events.append((t, f"gripper {j} refused: the robot has {gs.n} gripper(s)"))
            return
        name = self.model.grippers[j].name
        lo, hi = self.gripper_range(j)
        if cmd.grip == "travel":
            target = cmd.value
        elif cmd.grip == "force":
            if self.grasp.state[j] is GraspState.OPEN:
                self.events.append(
                    (t, f"gripper {name} squeeze refused: no contact sensed (close it first)")
                )
                return
            # eq. (43): F_BA = K_B (δ − L21), the object taken as rigid; the cable carries
            # F_BA on top of K_A δ (eq. (26)), so the imposed spring travel holds F_BA/K_A more
            target = float(self.grasp.contact_travel[j]) + cmd.value * (
                1.0 / float(gs.k_b[j]) + 1.0 / float(gs.k_a[j])
            )
        else:  # release: as open as the redundancy allows here
            target = lo + 0.002 if math.isfinite(lo) else math.nan
        if not (math.isfinite(target) and lo <= target <= hi):
            self.events.append(
                (
                    t,
                    f"gripper {name} {cmd.grip} refused: travel {target * 1e3:.1f} mm is outside "
                    f"what the redundancy gives here, [{lo * 1e3:.1f}, {hi * 1e3:.1f}] mm",
                )
            )
            return
        self.grip_target[j] = target
        self.events.append((t, f"gripper {name} {cmd.grip}: travel to {target * 1e3:.1f} mm"))

    def _hold_grippers(self) -> None:
        """Every gripper holds the travel it has: left to the minimum of energy, a jaw would
        wander with every change of the wrench, and its 10 kg on K_A (a ~1.6 Hz mode) fed the
        platform's loop a growing oscillation near the end of the other gripper's range
        (lock-step, seed000_grippers)."""
        gs = self.grippers
        if not gs.n:
            return
        travel = (self.hold_tensions[gs.cables] - self.jb_load) / gs.k_a
        for j in range(gs.n):
            if math.isnan(self.grip_target[j]):
                self.grip_target[j] = self.grip_imposed[j] = float(travel[j])
        self._apply_grip_impositions()

    def _ramp_grip_impositions(self) -> None:
        gs = self.grippers
        step = self.GRIP_SPEED * self.period
        changed = False
        for j in range(gs.n):
            target = self.grip_target[j]
            if math.isnan(target):
                continue
            cur = self.grip_imposed[j]
            if math.isnan(cur):
                cur = float(self.grasp.travel[j])
            new = cur + max(-step, min(step, target - cur))
            if new != self.grip_imposed[j]:
                self.grip_imposed[j] = new
                changed = True
        if changed:
            self._apply_grip_impositions()

    def _apply_grip_impositions(self) -> None:
        gs = self.grippers
        base = self.tda.options
        keep = tuple(i for i in base.impositions if i.cable not in gs.cables)
        # the moving ones last: at the end of its range the TDA saturates the last imposition
        # (the one being driven there), not a gripper that holds
        order = sorted(range(gs.n), key=lambda j: self.grip_imposed[j] != self.grip_target[j])
        grip = tuple(
            Imposition(int(gs.cables[j]), ImposedQuantity.DEFORMATION, float(self.grip_imposed[j]))
            for j in order
            if not math.isnan(self.grip_imposed[j])
        )
        self.impose(keep + grip)

    def impose(self, impositions: tuple[Imposition, ...]) -> None:
        """Switch the energy TDA's impositions (Sensors 2019 eq. (24)) from the next cycle,
        for the loop's and the stretch estimate's distribution alike (a tension planner calls
        it every cycle; values are the caller's to keep feasible and to ramp)."""
        base = self.tda.options
        opts = dataclasses.replace(base, method=TDAMethod.ENERGY, impositions=impositions)
        if base.method is not TDAMethod.ENERGY:  # once: the energy TDA's set-up
            self.tda = TensionDistributor(self.model, opts)
            self._static_tda = TensionDistributor(self.model, opts)
        self.tda.options = opts
        self._static_tda.options = opts

    def gripper_status(self) -> list[dict[str, Any]]:
        g = self.grasp
        force, energy = g.reported_force(), g.energies()
        return [
            {
                "cable": x.name,
                "state": g.state[j].value,
                "travel": float(g.travel[j]),
                "force": float(force[j]),
                "contact_travel": float(g.contact_travel[j]),
                "energy": float(energy[j]),
                "tension": float(g.tension[j]),
                "target": float(self.grip_target[j]),
            }
            for j, x in enumerate(self.model.grippers)
        ]

    def status(self) -> dict[str, Any]:
        e = self.estimator
        return {
            "state": self.state.value,
            "fault": self.fault_reason,
            "position": e.position.tolist(),
            "tensions": self.tensions.tolist(),
            "tda_status": self.tda_status.name,
            "cycle": self.cycle,
            **({"grippers": self.gripper_status()} if self.grippers.n else {}),
        }
