"""The drives held for a calibration (:class:`Session`): at the driver's period on its clock
(``wait``), so the same code runs in real time and in lock-step with the simulated robot;
position targets for the cables that hold lengths, a tension loop for the redundant ones, the
moves' stop rule and the limits that stop a procedure (drives disabled, brakes on)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from cdprctl.calibration.calibration_record import CalibrationRecord
from cdprctl.calibration.identify import Identified
from cdprctl.control.cycle.cable_kernels import force_feedback_kernel
from cdprctl.control.cycle.torques import WinchTorques, friction_kernel
from cdprctl.control.lifecycle.loop import periods_missed
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.geometry.stiffness import lowest_mode
from cdprctl.model.robot import RobotModel
from cdprctl.motion.trajectory import coordinates_rotation
from cdprctl.tda.hold import equilibrium_tensions
from drivers.base import WinchDriver
from drivers.vocabulary import Lifecycle, WinchStates


class CalibrationFailedError(Exception):
    """The procedure stopped (drives disabled, brakes on); the message says why. When the
    identification ran but was refused, ``record`` and ``identified`` hold what it found."""

    record: CalibrationRecord | None = None
    identified: Identified | None = None

    @classmethod
    def with_result(
        cls, record: CalibrationRecord, identified: Identified, message: str
    ) -> CalibrationFailedError:
        exc = cls(message)
        exc.record, exc.identified = record, identified
        return exc


class Session:
    """The drives held at the driver's period: position targets (rad), the torques (N·m) for
    ``tension_goal`` (N: the torque law with its friction, as the daemon's; feed-forward in
    position mode) and, for the ``force`` cables, a tension loop moving their targets.

    The tension loop: each cycle the target moves by ``gain`` of the tension error over the
    cable's stiffness (the error decays at ``gain`` a cycle, a first-order loop), plus a learnt
    ``drift`` scaled by the move's ``pace`` (``sin(π f)``: the cosine ramp's speed profile).
    A ramp planned on a geometry a few mm off asks each force cable for a length rate a little
    off, in proportion to the pace: the first-order loop alone follows it an error behind
    (CoGiRo's long moves: 30-60 N, slack cables at the ends); the drift learns that rate
    (``INTEGRAL_SHARE`` of the correction a cycle, per unit pace), and at rest (pace 0) the
    loop is the plain one."""

    # of each cycle's correction, per unit pace, added to the drift (a second integrator: a
    # ramp's constant rate error followed without lag; 0.25 damps it near critically)
    INTEGRAL_SHARE = 0.25
    # the damping's rate, × the daemon's (force_feedback × the lowest mode): 0.5 with a 5 Hz
    # filter and 0.2 with 3 Hz both carried CoGiRo's seed 1 through (anchors within 0.08 and
    # 0.16 mm; it stopped without); the filter below the servo's own torque, above the ring
    DAMPING_SHARE = 0.5
    DAMPING_FILTER = 5.0

    def __init__(self, model: RobotModel, driver: WinchDriver, log: Callable[[str], None]):
        self.model, self.driver, self.log = model, driver, log
        m = model.n_cables
        self.ratio = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
        self.csp = model.drives.holds_lengths
        self.targets = np.zeros(m)  # rad: base + correction
        self.base = np.zeros(m)  # rad: where the plan puts each motor
        self.correction = np.zeros(m)  # rad: the force cables' tension loop
        self.torques = np.zeros(m)  # N·m: out, from tension_goal every cycle
        self.tension_goal = np.zeros(m)  # N: every cable's, held by the force cables' loop
        self.winches = WinchTorques(model)
        self._all = np.arange(m)
        self._friction = np.zeros(m)  # N·m, at the measured motor speeds
        self._no_WT, self._no_acceleration = np.zeros((m, 6)), np.zeros(6)
        self.pace = 0.0  # the move's speed profile, sin(π f); 0 at rest
        self.drift = np.zeros(m)  # rad per cycle at pace 1: the force cables' learnt rate
        self.force = np.zeros(m, dtype=bool)
        self.gain = 0.0  # per cycle, of the tension loop
        kin = KinematicsData(model)
        inverse_kinematics(model, kin, model.home.position, model.home.rotation)
        self.k = model.cable_stiffness(kin.length)  # N/m (the tension loops' scale)
        # the position-held cables damped (integral force feedback, as the daemon's cable
        # space does: cable_space.py) on their tensions low-passed at DAMPING_FILTER
        self.iff = self.DAMPING_SHARE * model.control.force_feedback * lowest_mode(model)
        self.give = np.zeros(m)  # m each position-held cable is paid out
        self._tension_error = np.zeros(m)  # N: filtered − goal
        self.filtered = np.zeros(m)  # N: the tensions low-passed
        self._active_for = 0.0  # s enabled: the torques are tensions once the brakes opened
        self._release = model.drives.brake_release_time  # s
        self.t_low = 0.3 * model.tension_min  # N: below, a cable is going slack: stop
        self.t_high = model.tension_max  # N
        span = model.tension_max - model.tension_min
        self.t_stop_low = model.tension_min + 0.1 * span  # N: a move stops here
        self.t_stop_high = model.tension_max - 0.15 * span  # N
        self.states: WinchStates = driver.states
        self.stopped_by = ""  # why the last move stopped short (a cable, its tension)
        self.missed_periods = 0  # cycles skipped: this process held up beyond a period
        self.cycles = 0  # periods the session ran, the missed ones included
        self.cycle_time = driver.period  # s the cycle under way stands for (missed included)
        self._outside = 0.0  # s a tension has been outside its bounds
        self._before = np.zeros(m)  # N: the tensions a move started from
        self._beyond = np.zeros(m)  # s each tension has been where a move stops

    # s: a tension outside its bounds this long stops the procedure (a transient, such as the
    # first feedback after the enable, does not)
    OUTSIDE_FOR = 0.1
    # s a tension stays beyond where a move stops before it does (at least 2.5 periods): a
    # transient does not (across processes, real time, rowc's geometric moves stopped at
    # 1-56 % on single-cycle spikes that the samples at rest never showed; lock-step 67-91 %)
    STOP_PERSISTS = 0.02

    def begin_move(self) -> None:
        """Before a move: the tensions it starts from (``move_stops`` compares with them)."""
        self._before[:] = self.tensions()
        self._beyond[:] = 0.0
        self.stopped_by = ""
        self.drift[:] = 0.0  # another move, another rate

    def move_stops(self) -> bool:
        """Called every cycle of a move: whether a tension has stayed beyond ``t_stop_low`` /
        ``t_stop_high`` and further that way than at the move's start (by 1 N) for
        ``STOP_PERSISTS``; ``stopped_by`` then says which cable, at what."""
        t = self.tensions()
        high = (t > self.t_stop_high) & (t > self._before + 1.0)
        low = (t < self.t_stop_low) & (t < self._before - 1.0)
        self._beyond[:] = np.where(high | low, self._beyond + self.cycle_time, 0.0)
        persisted = self._beyond >= max(self.STOP_PERSISTS, 2.5 * self.driver.period)
        if not np.any(persisted):
            return False
        i = int(np.flatnonzero(persisted)[0])
        limit = self.t_stop_high[i] if high[i] else self.t_stop_low[i]
        self.stopped_by = (f"cable {self.model.cables[i].name} at {t[i]:.1f} N (it stops a "
                           f"move beyond {limit:.1f} N)")  # fmt: skip
        return True

    def tensions(self) -> np.ndarray:
        """N: the tensions the drives' torques hold, the winches' friction at the measured
        motor speeds taken out (moving, friction takes a part of the torque: rowc's samples
        read it as tension, the identified anchors were off by 1.6-6.9 mm; at rest, speed 0,
        it is 0). The rotor's inertia is neglected: the moves are slow."""
        w = self.winches
        friction_kernel(w.terms, self.states.velocity, self._all, self._friction)
        return (self.states.torque - self._friction) / self.ratio

    def run(self, duration: float, each: Callable[[float], bool | None] | None = None) -> float:
        """Hold for ``duration`` s; ``each(fraction)`` sets targets/torques every cycle and
        ends the run after that cycle by returning True (a move that stopped: the rest would
        only hold). Returns the seconds run.

        A cycle held up more than a period (this process stalled: in the wait, the last
        write or this read) skips the periods it missed instead of running them in a burst
        (their SYNCs bunched: following-error faults), and the fraction moves on by what the
        drives extrapolated meanwhile (``[drives] target_extrapolation``), the rest of the
        stall waited out: moving on by all of it, the next target stepped ahead of the held
        drives; by none, behind the extrapolated ones (the daemon's reference does the same).
        The persistence timers count the time the cycle stands for."""
        d = self.driver
        period = d.period
        deadline = d.clock()  # when the next cycle is due
        n = max(1, round(duration / period))
        extrapolated = max(0, math.floor(self.model.drives.target_extrapolation / period + 1e-9))
        i = 0
        while i < n:
            now = d.clock()
            self.states = d.read(now)
            missed = periods_missed(d.clock() - deadline, period)
            if missed:
                self.missed_periods += missed
                deadline += missed * period
                if i > 0:  # a ramp under way: the drives went on along it
                    i = min(i + min(missed, extrapolated), n - 1)
            self.cycle_time = (1 + missed) * period
            self.cycles += 1 + missed
            if d.lifecycle is Lifecycle.ERROR:
                raise CalibrationFailedError(f"the drives stopped: {d.error}")
            ends = each is not None and bool(each((i + 1) / n))
            if self.force.any() and d.lifecycle is Lifecycle.ACTIVE:
                self._tension_loop()
            np.add(self.base, self.correction, out=self.targets)
            self._damp(d.lifecycle is Lifecycle.ACTIVE)
            t = self.tensions()
            outside = d.lifecycle is Lifecycle.ACTIVE and bool(
                np.any(t > self.t_high) or np.any(t < self.t_low)
            )
            self._outside = self._outside + self.cycle_time if outside else 0.0
            if self._outside > self.OUTSIDE_FOR:
                worst = int(np.argmax(np.maximum(t - self.t_high, self.t_low - t)))
                raise CalibrationFailedError(
                    f"cable {self.model.cables[worst].name} at {t[worst]:.1f} N, outside "
                    f"[{self.t_low[worst]:.1f}, {self.t_high[worst]:.1f}] N for "
                    f"{self.OUTSIDE_FOR:g} s: stopped"
                )
            self.winches.update(self.tension_goal, self._no_WT, self._no_acceleration,
                                self.states.velocity, True, self.torques)  # fmt: skip
            d.write(now, self.torques, targets=self.targets if self.csp else None)
            deadline += period
            i += 1
            d.wait(max(0.0, deadline - d.clock()))
            if ends:
                break
        return i * period

    def _damp(self, active: bool) -> None:
        """The position-held cables' targets paid out by the leaky integral of their tension
        error (``force_feedback_kernel``, rate ``iff``) on the tensions low-passed at
        ``DAMPING_FILTER`` Hz — from the brakes' release on. Undamped, CoGiRo's platform rang
        at ~2 Hz on its drives' position loops (40 kg of reflected inertia per winch), a swing
        of ±200 N that grew along its 0.2 m/s moves until a cable went slack: 13 of 20 seeded
        calibrations stopped. On the raw torque readings the same feedback oscillated at half
        the cycle rate within 30 ms (the servo's own torque fed back)."""
        self._active_for = self._active_for + self.cycle_time if active else 0.0
        if self._active_for <= self._release:
            self.filtered[:] = self.tension_goal
            return
        a = 1.0 - math.exp(-2.0 * math.pi * self.DAMPING_FILTER * self.cycle_time)
        self.filtered += a * (self.tensions() - self.filtered)
        if self.iff <= 0.0:
            return
        np.subtract(self.filtered, self.tension_goal, out=self._tension_error)
        self._tension_error[self.force] = 0.0  # those follow their own loop
        force_feedback_kernel(self._tension_error, self.k, math.exp(-self.iff * self.cycle_time),
                              self.give)  # fmt: skip
        np.divide(self.give, self.ratio, out=self._tension_error)  # rad: the buffer reused
        self.targets -= self._tension_error  # paid out: θ > 0 winds in

    def _tension_loop(self) -> None:
        """The force cables' targets moved towards their ``tension_goal`` (class docstring)."""
        step = self.gain * (self.tension_goal - self.tensions()) / (self.k * self.ratio)
        self.drift += self.INTEGRAL_SHARE * self.pace * step
        step += self.pace * self.drift
        self.correction[self.force] += step[self.force]

    def enable(self, timeout: float = 3.0) -> None:
        d = self.driver
        self.states = d.read(d.clock())
        self.base[:] = self.states.position
        self.correction[:] = 0.0
        d.begin_activate()
        waited = 0.0
        while d.lifecycle is not Lifecycle.ACTIVE:
            self.run(d.period)
            waited += d.period
            if waited > timeout:
                raise CalibrationFailedError(f"the drives did not enable in {timeout:g} s")

    def average(self, duration: float) -> tuple[np.ndarray, np.ndarray, float]:
        """Motor angles (rad) and tensions (N) averaged over ``duration`` s of holding, and
        the largest motor speed seen (rad/s)."""
        m = self.model.n_cables
        theta, tension, speed, n = np.zeros(m), np.zeros(m), [0.0], [0]

        def add(_: float) -> None:
            theta[:] += self.states.position
            tension[:] += self.tensions()
            speed[0] = max(speed[0], float(np.max(np.abs(self.states.velocity))))
            n[0] += 1

        self.run(duration, add)
        return theta / n[0], tension / n[0], speed[0]

    def move(self, goal: np.ndarray, tensions: np.ndarray, duration: float) -> float:
        """Over ``duration`` s (a cosine ramp): the planned motor angles to ``goal`` (rad; the
        force cables' tension loop corrects theirs), the force cables' tension and every
        feed-forward to ``tensions`` (N). A tension beyond ``t_stop_low/high`` and moving
        further that way stops the ramp where it is (``move_stops``; the start is only near
        home: the real tensions differ from the plan's). Returns the fraction of the ramp
        done."""
        start = self.base.copy()
        t_start = self.tension_goal.copy()
        reached = [0.0, False]  # the ramp's fraction, stopped
        self.begin_move()

        def ramp(f: float) -> None:
            if reached[1]:
                return
            if self.move_stops():
                reached[1] = True  # a tension near its limit: the pose goes no further
                self.pace = 0.0
                return
            a = 0.5 - 0.5 * math.cos(math.pi * f)
            reached[0] = a
            self.pace = math.sin(math.pi * f)
            self.base[:] = start + a * (goal - start)
            self.tension_goal[:] = t_start + a * (tensions - t_start)

        self.run(duration, ramp)
        self.pace = 0.0
        return reached[0]

    def close(self) -> None:
        self.driver.deactivate()
        if self.missed_periods:
            self.log(f"  the procedure's cycles: {self.missed_periods} periods missed (this "
                     "process was held up; the moves waited them out)")  # fmt: skip


def hold_tensions(model: RobotModel, kin: KinematicsData, x: np.ndarray) -> np.ndarray:
    """N: the tensions holding the platform's weight at ``x`` (m; rotation vector from home)."""
    inverse_kinematics(model, kin, x[:3], coordinates_rotation(model.home.rotation, x[3:]))
    return equilibrium_tensions(model, kin)
