"""The fast loop in cable space, for drives in cyclic synchronous position (``[drives] mode =
"csp"``): each winch gets a position target with its torque as feed-forward, and the drive's
own position loop (kHz, in the drive) holds the cable's unstretched length.

Why: with torque-controlled winches a cable's tension does not depend on its length, so the
platform is held only by the pose loop, whose gain the worst-conditioned direction and the
feedback delay limit (rowc's y: 0.6 Hz; its 30 N water jet moved it 55 mm at 500 Hz and
faulted at 250 Hz). Holding the lengths makes the cables' own elasticity the stiffness — the
stiffness the SOTDA maximises (Picard et al. 2020, eq. (7)) — at every rate, and the pose loop
only corrects slowly on top (docs/control.md has the measurements).

* Targets: the cables' geometric lengths at the trajectory's reference pose (inverse
  kinematics), less their stretch under the commanded tensions, ``l0 = l − t c(l0)`` (the cable
  law of ``numerics``), as motor angles ``θ = (l_zero − l0)/(r/G)`` (``l_zero``: the
  estimator's, where each encoder reads zero). Out of the active states the target is where
  each motor is, so enabling starts without a step.
* The pose feedback is off in this mode (``wrench.py`` says why): the estimator's stretch uses
  the commanded tensions, the ones the targets were stretched by, so the estimate is the pose
  the drives' lengths give (their tracking error shows; a force the controller does not know
  deflects the platform by the cables' elasticity, unseen — as on the ARK 2020 prototype).
* The external wrench: what the cables exert beyond what was commanded, ``W (t_meas − t_cmd)``,
  balances at rest the part of an unknown force not yet compensated; integrated at
  ``[control] disturbance_bandwidth`` it converges to that force, which is fed forward (the
  TDA distributes it: the SOTDA and the feasibility check see the real jet) and published
  (``external_wrench_estimate``). The deflection it caused then goes as the targets' stretch
  follows the new tensions.
* Damping: the cables' own is ~2 % (rowc's y mode, 3.1 Hz, rang for seconds after a force
  switched off, and the external-wrench loop made it grow): each cable is paid out by the
  integral of its tension error, leaking back (integral force feedback, Preumont, "Vibration
  Control of Active Structures"): collocated per cable, it damps every mode whose energy is
  in the cables, at gain = leak = the platform's lowest mode (``[control] force_feedback``).
* Measured tensions: from the drives' torques less friction and rotor inertia (the torque law
  taken back, ``torques.applied_tension``), low-passed at ``MEASURED_TENSION_FILTER``;
  published (telemetry ``measured_tensions``), and compared with the commanded ones through
  the same filter: the difference's part in the null space of W is what the cables pull
  against each other beyond what was asked — a cable whose length is not what its encoder
  says (encoder jump, slip, snap; the supervisor's ``CABLE_TENSION`` check), while a force
  on the platform shows in the other part. Not fed to the estimate: on rowc 0.1 N of
  tension error is millimetres of y (28 mm of estimated y during a move, lock-step).
"""

from __future__ import annotations

import math

import numpy as np

from cdprctl.control.cycle.cable_kernels import (
    after_stall_kernel,
    disturbance_kernel,
    force_feedback_kernel,
    internal_part_kernel,
    measured_tension_kernel,
    motor_target_kernel,
    tension_hold_kernel,
)
from cdprctl.control.data import ControlData
from cdprctl.core.numerics import min2
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.stiffness import lowest_mode
from cdprctl.model.robot import RobotModel

#: the winding (``Estimator.winding``): the cable law's terms, l_zero (m), r/G (m/rad)
Winding = tuple[tuple, FloatArray, FloatArray]

#: the external-wrench estimate's bandwidth: the platform's lowest mode over this
DISTURBANCE_BELOW_MODE = 6.0


def disturbance_bandwidth(model: RobotModel) -> float:
    """Hz: ``[control] disturbance_bandwidth``, or from the model where not set: the
    platform's lowest mode on its cables (``stiffness.lowest_mode``) over
    ``DISTURBANCE_BELOW_MODE``. The estimate reads the force from the cables' stretch, which
    is quasi-static only well below that mode. Measured in lock-step (30 N ramped in over
    1 s, with the force feedback's damping): rowc (3.08 Hz) rang at 1 Hz and went unstable at
    2 Hz; the Sensors 2019 springs (0.39 Hz) kept swinging at a third of the mode and grew at
    two thirds (74 mm), at a sixth both brought the jet back (rowc 6.5 mm peak, 0.51 Hz: the
    0.5 Hz it was tuned to by hand; seed000 0.09 mm after 20 s)."""
    c = model.control.disturbance_bandwidth
    if c is not None:
        return c
    return lowest_mode(model) / (2.0 * math.pi) / DISTURBANCE_BELOW_MODE


class CableSpace:
    """``targets`` → ``data.motor_target``; ``measure`` → ``data.measured_tensions``."""

    # a cycle this many periods after the last is a stall the drives went on through
    LATE = 1.5
    # s: the time constant over which a deviation the drives went into during a stall is
    # taken back (critically damped); on the spring robot, 0.5 rad peak at 18 rad/s
    CATCH_UP = 0.01

    # Hz: the measured tensions' low-pass; below the winch-on-cable modes (23-34 Hz on the
    # shipped robots), above the pose loop
    MEASURED_TENSION_FILTER = 5.0
    # Hz: the same for the supervision's internal tension error
    SUPERVISION_FILTER = 20.0
    # rad/s: a controlled stop reels in every cable that lost tension (a winch that slipped:
    # the cable lengthened where the encoder cannot see it) at the rate of the error it acts
    # on, the supervision's filter. The leaky force feedback gives back at most its tension
    # over its stiffness (2.4 mm on rowc) while the stop held the motors: the slipping cable
    # went slack and rowc swung 25.4 mm along its elastic y; reeled in, 8.5 mm (torque mode,
    # which keeps tensions by itself, 10.3; at half this rate 10.4, a quarter 13.4, twice 7.5
    # with a snapped cable's 34.8 mm going to 35.6; lock-step, the reliability table's runs).
    # Never paid out: a ratchet that takes back only lost length
    TENSION_HOLD = 2.0 * math.pi * SUPERVISION_FILTER
    # s: enabling takes the cables from the tensions they carry (what the brakes held) to the
    # commanded ones in this time, the drives starting where the motors are. Parked by another
    # distribution (a config changed since), the difference is internal force no pose
    # explains (rowc, barycenter against SOTDA ν = 0.9: up to 87 N, 0.24 rad at the motor):
    # taken in one step it faulted a drive on its following error at 1 kHz. Slow beside the
    # winch-on-cable modes (23-34 Hz), short beside anything a user commands.
    ENABLE_SETTLE = 0.5

    def __init__(self, model: RobotModel, data: ControlData):
        """The stages it reads are given in each call: the lengths and stiffness at the
        reference (``ReferencePose``), the winding (``Estimator.winding``), the winch law's
        terms (``WinchTorques.terms``, which a friction calibration replaces)."""
        self.enabled = model.drives.holds_lengths
        self.data = data
        # s: the instant each drive sampled its last feedback taken, and that sample's motor
        # speed (rad/s): the measured tensions step by the samples' own interval
        self._last_sampled = np.full(model.n_cables, -math.inf)
        self._last_velocity = np.zeros(model.n_cables)
        self._commanded = np.zeros(model.n_cables)  # N, the commanded tensions low-passed
        self._fast_error = np.zeros(model.n_cables)  # N, at SUPERVISION_FILTER
        # the measured tensions' filter state, as measured_tension_kernel takes it
        self._measuring = (self._last_sampled, self._last_velocity, self._commanded,
                           self._fast_error)  # fmt: skip
        self.give = np.zeros(model.n_cables)  # m, paid out by the force feedback
        m = model.n_cables
        # m, paid out at enable so the targets start where the motors are, to none over
        # ENABLE_SETTLE (smoothstep: no velocity step at either end)
        self.settle = np.zeros(m)
        self._settle0 = np.zeros(m)  # m: at enable
        # of it left, per cable (a float operand built an array a call, a broadcast one a
        # buffer)
        self._share = np.zeros(m)
        self._settle_time = math.inf  # s since enable (nan: the first active cycle takes it)
        self._settle_rad = np.zeros(m)  # rad: the settle at the motor
        # N: the tensions the cables should carry, the commanded ones less what the settle
        # still pays out: what the measured ones are compared with (the tensions the brakes
        # left are no disagreement). Not the torque feed-forward: after a slipped winch the
        # forward kinematics spreads its 25 mm over the other cables, and their 40 kN/m made
        # that 200 N (1.84 N·m, 1.09 from the commanded tensions) where they carried 117 N
        self.expected = np.zeros(m)
        self._t_lo, self._t_hi = model.tension_min.copy(), model.tension_max.copy()  # N
        # s: the drives' torque is taken as the tensions once this long enabled
        self._release = model.drives.brake_release_time
        self._measured_for = 0.0  # s since the first measured cycle after enabling
        # m/s: a stop reels a cable in no faster than the platform may move (on a spring of
        # a few hundred N/m, a deficit of a few newtons would reel metres per second)
        self._reel_speed = model.control.max_velocity
        # rad/s: its gain and leak, the platform's lowest mode times [control] force_feedback
        # (Preumont's integral force feedback damps a mode best near its own frequency; on
        # rowc 10-20 rad/s took the y ring from 2 % damping to none left after 2 s, higher
        # gains made the platform yield to the jet: lock-step, measured)
        factor = model.control.force_feedback
        self.iff = factor * lowest_mode(model) if self.enabled and factor > 0.0 else 0.0
        self.disturbance_bandwidth = disturbance_bandwidth(model)  # Hz
        self.disturbance_gain = 2.0 * math.pi * self.disturbance_bandwidth  # rad/s
        # after a stall (``_after_stall``): the targets last sent (rad), the rate each drive
        # took for them (rad/s), the deviation carried on (rad) and its rate (rad/s)
        self._period = model.control.period  # s
        self._extrapolation = model.drives.target_extrapolation  # s
        self._sent = np.zeros(m)
        self._sent_valid = False
        self._drive_rate = np.zeros(m)
        self._deviation = np.zeros(m)
        self._deviation_rate = np.zeros(m)
        self._no_cells = np.full(m, math.nan)  # N: no load cell on any cable

    def targets(self, active: bool, motor_position: FloatArray, lengths: FloatArray,
                k: FloatArray, winding: Winding) -> None:  # fmt: skip
        """``data.motor_target`` (rad): from the reference pose (its cables' ``lengths`` m
        and stiffness ``k`` N/m) and the commanded tensions on the ``winding`` when
        ``active``, carried on from where the drives went during a stall (``_after_stall``),
        else the motors' own ``motor_position`` (rad); ``expected`` (N)."""
        self._targets(active, motor_position, lengths, k, winding)
        self._after_stall(active)

    def _after_stall(self, active: bool) -> None:
        """After a cycle later than ``LATE`` periods the drives have gone on at their last
        rate (``[drives] target_extrapolation``) past where the reference now is — on the
        spring robot by up to half a radian when the stall spans a jerk step of the
        trajectory (the stretch's speed steps with it: ~60 rad/s at the motor, 4 m/s³). The next
        target there made the drive reverse, a following-error fault. Instead the targets
        carry that deviation on and take it back critically damped over ``CATCH_UP``
        (``x(t) = x₀ (1 + t/τ) e^(−t/τ)``: no step of speed at its start, at most
        ``x₀ / (e τ)``); between two cycles the drives' position loops see no reversal."""
        d = self.data
        if not active or not self._sent_valid:
            self._deviation[:] = 0.0
            self._deviation_rate[:] = 0.0
            self._drive_rate[:] = 0.0
            self._sent[:] = d.motor_target
            self._sent_valid = active
            return
        dt = d.dt
        after_stall_kernel(
            d.motor_target, self._sent, self._drive_rate, self._deviation, self._deviation_rate,
            dt, self._period, min2(dt, self._extrapolation), dt > self.LATE * self._period,
            self.CATCH_UP,
        )  # fmt: skip

    def _targets(self, active: bool, motor_position: FloatArray, lengths: FloatArray,
                 k: FloatArray, winding: Winding) -> None:  # fmt: skip
        d = self.data
        if not active:
            d.motor_target[:] = motor_position
            self.expected[:] = d.tensions
            return
        law, l_zero, drum_ratio = winding
        motor_target_kernel(
            lengths, d.tensions, law, l_zero, drum_ratio, self.give, d.motor_target
        )  # fmt: skip
        if math.isnan(self._settle_time):  # the first active cycle: what the motors lack
            np.subtract(d.motor_target, motor_position, out=self._settle0)
            np.multiply(self._settle0, drum_ratio, out=self._settle0)
            self._settle_time = 0.0
        else:
            self._settle_time += d.dt
        x = self._settle_time / self.ENABLE_SETTLE
        if x >= 1.0:  # settled: the targets as they are, the commanded tensions expected
            self.settle.fill(0.0)  # fill, copyto: no view built, as a slice would
            np.copyto(self.expected, d.tensions)
            return
        self._share.fill(1.0 - x * x * (3.0 - 2.0 * x))
        np.multiply(self._settle0, self._share, out=self.settle)
        # paid out like the force feedback's give: the motor angle less settle / (r/G)
        np.divide(self.settle, drum_ratio, out=self._settle_rad)
        np.subtract(d.motor_target, self._settle_rad, out=d.motor_target)
        np.multiply(k, self.settle, out=self.expected)
        np.subtract(d.tensions, self.expected, out=self.expected)
        # within the cables' range: a length the model has wrong by millimetres would make
        # hundreds of newtons of a stiff cable
        np.maximum(self.expected, self._t_lo, out=self.expected)  # np.clip's rule, in two
        np.minimum(self.expected, self._t_hi, out=self.expected)  # ufuncs: no block

    def start_measuring(self) -> None:
        """The measured and commanded tensions start from the holding ones (enable)."""
        d = self.data
        d.measured_tensions[:] = d.hold_tensions
        self._commanded[:] = d.hold_tensions
        d.tension_error[:] = 0.0
        d.internal_tension_error[:] = 0.0
        self._fast_error[:] = 0.0  # (data.ext_estimate: zeroed by the observer's reset)
        self.give[:] = 0.0
        self.settle[:] = 0.0
        self._settle_time = math.nan
        self._measured_for = 0.0
        self._last_sampled[:] = -math.inf  # the first sample after enabling starts the count

    def warm_up(self, N: FloatArray, terms: tuple) -> None:
        """``measure``'s and ``_after_stall``'s kernels compiled, past the brake-release
        window (on throwaway outputs: the caller keeps what it needs; enabling starts the
        measurement afresh)."""
        zeros = np.zeros(self.data.measured_tensions.shape[0])
        self._measured_for = math.inf
        self.measure(zeros, zeros, zeros, N, terms)
        self._measured_for = 0.0
        self._last_sampled[:] = -math.inf
        s, T = np.zeros((5, zeros.shape[0])), self._period
        after_stall_kernel(s[0], s[1], s[2], s[3], s[4], 2.0 * T, T, 2.0 * T, True, self.CATCH_UP)

    def force_feedback(self, k: FloatArray, stopping: bool = False) -> None:
        """``give`` (m): each cable paid out by the integral of its tension error, leaking
        back (``force_feedback_kernel``), at the rate ``self.iff`` (rad/s). ``stopping`` (a
        controlled stop): instead, each cable that carries less than it should is reeled in
        to its tension at ``TENSION_HOLD`` rad/s, no faster than ``[control] max_velocity``
        (``tension_hold_kernel``). ``k`` (N/m): the cables' stiffness at the reference."""
        d = self.data
        if stopping:
            tension_hold_kernel(
                self._fast_error, k, self.TENSION_HOLD * d.dt,
                self._reel_speed * d.dt, d.measured_tensions, self._t_lo, self.give,
            )  # fmt: skip
        elif self.iff > 0.0:
            decay = math.exp(-self.iff * d.dt)
            force_feedback_kernel(d.tension_error, k, decay, self.give)

    def estimate_disturbance(self, W: FloatArray, integrate: bool, ext: FloatArray) -> None:
        """``ext`` (``data.ext_estimate``; N, N·m at P, base frame), integrated in place: the
        external wrench from the measured tensions (``disturbance_kernel``), while
        ``integrate`` — held while the
        feedback or the distribution saturates, so that a force beyond what the cables can
        hold is not wound up (the feed-forward then stays infeasible and the supervisor
        stops: ``FaultKind.TENSION_DISTRIBUTION``)."""
        d = self.data
        if integrate and self.disturbance_gain > 0.0:
            disturbance_kernel(W, d.tension_error, self.disturbance_gain * d.dt, ext)

    def measure(
        self, torque: FloatArray, velocity: FloatArray, sampled_at: FloatArray, N: FloatArray,
        terms: tuple, cells: FloatArray | None = None,
    ) -> None:  # fmt: skip
        """``data.measured_tensions`` (N) from the drives' ``torque`` (N·m) and ``velocity``
        (rad/s), sampled at ``sampled_at`` (s, each drive's SYNC), the rotor's inertia taken out at
        the acceleration the samples show (``measured_tension_kernel``); ``data.tension_error``
        and its ``internal_tension_error`` part in the null space ``N`` (m × r, orthonormal)
        of the wrench matrix. For ``[drives] brake_release_time`` after enabling nothing is
        measured: the tensions stay the holding ones, no error.
        Why the samples' own times and accelerations: on the spring robot each motor's target
        speed stepped ~50 rad/s as a move started at 4 m/s³ (the stretch follows the tensions'
        rate), and the rotor's inertia torque was read as 30-40 N of tension (the trajectory's
        acceleration has no stretch in it); one cycle held up 6 ms there weighted that sample
        by the cycle's 8 ms instead of the 2 ms it covered: 136 N, the force feedback paid
        out 0.52 rad, the drive reversed and faulted on its following error (seed000, 500 Hz,
        lock-step; docs/control.md "Measured tensions"). ``cells`` (N per cable, NaN: none):
        the load cells' tensions, measured where a cable has one (``tension_source.py``);
        ``terms``: the winch law's (``WinchTorques.terms``)."""
        d = self.data
        self._measured_for += d.dt
        if self._measured_for <= self._release:
            return
        measured_tension_kernel(
            torque, velocity, sampled_at, terms, self.expected, self.MEASURED_TENSION_FILTER,
            self.SUPERVISION_FILTER, self._measuring, d.measured_tensions, d.tension_error,
            self._no_cells if cells is None else cells,
        )  # fmt: skip
        internal_part_kernel(N, self._fast_error, d.internal_tension_error, d.internal_leverage)
