"""An ODrive axis's position-mode settings from the robot's model: its cascaded loops' gains,
its velocity limit and its current limit, in the units ODrive's CAN Simple messages carry.

ODrive's position mode is a cascade (docs.odriverobotics.com, "Control Structure and Tuning";
firmware ``Controller::update``): ``vel_des = pos_gain (pos_setpoint − pos) + vel_ff``, clamped
to ``vel_limit``; ``torque = vel_gain (vel_des − vel) + integrator + torque_ff``. Without the
integrator and the clamp it is the CiA 402 drives' loop ``kp (θ_t − θ) + kd (θ̇_t − θ̇)``
(``DrivesConfig.position_gains``: the rotor at ``position_loop_bandwidth``, damping 0.7) with
``vel_gain = kd`` and ``pos_gain = kp / kd``: one rule for both protocols, with one bound.
A CiA 402 drive interpolates its targets between SYNCs; an ODrive in passthrough holds each
Set_Input_Pos for a period: its loop pulls ``kp · rate · (T/2 − τ)`` more than an interpolating
drive τ into the hold (the driver holds the middle of the period's path), a sawtooth of which
the rotor's acceleration takes a share and the cable the rest. The torque the driver reads,
asked for at the end of each hold, is taken less that share (``hold_ripple``): without it the
reading is off by up to ``kp · rate · T / 2`` (1 N·m on rowc at 0.3 m/s and 50 Hz: 100 N of
cable). rowc at 250 Hz, lock-step, its demo's moves, the loop at 50 Hz: tracking 0.011 mm RMS
with the share, 0.47 with all of the pull taken out; the cable's tension swings by 1.8 N at most
within a period (0.5 N with the loop at 25 Hz, 0.4 N with CiA 402 drives). The loop sits at most
a fifth of the control rate (``STEPS_PER_LOOP``): rowc at 125 Hz tracked 0.023 mm RMS and took
the 30 N jet within 8.6 mm with its loop at 25 Hz (a fifth), 0.040 mm and 16.9 mm at 12.5 Hz (a
tenth, the bound before the share was known).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import expm

TWO_PI = 2.0 * math.pi
# the velocity limit over the fastest cable speed a planned motion asks for: room for the
# pose loop's corrections and a disturbance's ride-through; ODrive's overspeed error trips at
# its vel_limit_tolerance (1.2 by default) times the limit
VELOCITY_LIMIT_MARGIN = 2.0
# control periods per period of the axis's position loop, at the least (module docstring)
STEPS_PER_LOOP = 5.0


@dataclass(frozen=True)
class AxisGains:
    """One axis's settings, in ODrive's units (turns of the motor)."""

    bandwidth: float  # Hz: the position loop's
    kp: float  # N·m/rad: the loop's stiffness (vel_gain · pos_gain in radians)
    pos_gain: float  # (turn/s)/turn = 1/s
    vel_gain: float  # N·m/(turn/s)
    # N·m/turn: none. The torque feed-forward carries the load; an integral on every winch's
    # loop grew rowc's 3 Hz y mode from 0.5 to 9 mrad in 2 s (sim_backend servo.servo_torque)
    vel_integrator_gain: float
    vel_limit: float  # turn/s of the motor
    current_limit: float  # A
    # the share of the loop's pull kp (setpoint − target) in the torque sampled at the end of
    # a hold that accelerates the rotor within the staircase (``hold_ripple``)
    ripple: float

    def line(self) -> str:
        return (
            f"pos_gain {self.pos_gain:.4g} (turn/s)/turn, vel_gain "
            f"{self.vel_gain:.4g} N·m/(turn/s), vel_integrator_gain "
            f"{self.vel_integrator_gain:g}, vel_limit {self.vel_limit:.3g} turn/s, current limit "
            f"{self.current_limit:.3g} A"
        )


def fastest_cable_speed(model: Any, cable: int) -> float:
    """m/s: the fastest cable ``cable`` pays out or winds in under a planned motion, bounded by
    ``[control] max_velocity`` + ``max_angular_velocity`` × its attachment's distance from the
    platform's origin (the attachment's speed, of which the cable's is a projection)."""
    ctl = model.control
    b = model.cables[cable].attachment
    return float(ctl.max_velocity + ctl.max_angular_velocity * math.sqrt(sum(x * x for x in b)))


def hold_ripple(inertia: float, kp: float, kd: float, period: float) -> float:
    """The share of the pull ``kp (setpoint − target)`` in the torque an axis in passthrough
    applies at the end of holding a setpoint, over the torque a drive interpolating the same
    targets would apply: what the staircase spends accelerating the rotor (kg·m² ``inertia``,
    the loop's ``kp`` N·m/rad and ``kd`` N·m·s/rad, the hold ``period`` s).

    Along a target moving at ``v``, the setpoint held over a period is the middle of the path
    (its Set_Input_Pos), so the loop pulls ``kp v (T/2 − τ)`` more than an interpolating drive
    at τ into the hold: a sawtooth. In its periodic steady state the rotor answers it as
    ``J ẍ + kd ẋ + kp x = kp v (T/2 − τ)``; at τ = T the axis applies
    ``−kp v T/2 − kp x(T) − kd ẋ(T) = J ẍ(T)`` more than the interpolating drive, returned
    here as a share of ``−kp v T/2`` (0.707 with the loop at a fifth of the rate, 0.853 at a
    tenth; it depends on ω T and ζ alone). Solved exactly
    with the sawtooth as state (``[x, ẋ, f, 1]``, ``ḟ = −1``; one period's transition by the
    matrix exponential, the periodic start from it). The cable's stiffness at the motor
    (``k r²``, up to 20 N·m/rad on rowc) moves it by < 1 %: left out, so the axis's own gains
    are all it needs."""
    T = period  # the generator over one period (time in periods: its entries are all O(1))
    a = np.array([
        [0.0, T, 0.0, 0.0],
        [-kp * T / inertia, -kd * T / inertia, kp * T / inertia, 0.0],
        [0.0, 0.0, 0.0, -T],
        [0.0, 0.0, 0.0, 0.0],
    ])  # fmt: skip
    e = expm(a)
    # [x, ẋ] periodic: (I − E₁₁) s = E₁₂ [T/2, 1]
    s = np.linalg.solve(np.eye(2) - e[:2, :2], e[:2, 2:] @ np.array([0.5 * period, 1.0]))
    pull = 0.5 * kp * period  # per unit of v: the interpolating drive's setpoint is ahead
    return float((pull + kp * s[0] + kd * s[1]) / pull)


def loop_bandwidth(model: Any, period: float) -> float:
    """Hz: ``[drives] position_loop_bandwidth``, at most a fifth of the control rate."""
    return min(model.drives.position_loop_bandwidth, 1.0 / (STEPS_PER_LOOP * period))


def axis_gains(model: Any, cable: int, period: float) -> AxisGains:
    """The settings of cable index ``cable``'s axis at the control ``period`` (s) (needs
    ``[drives] torque_constant``)."""
    drives, winch = model.drives, model.cables[cable].winch
    bandwidth = loop_bandwidth(model, period)
    kp, kd = drives.position_gains(winch.rotor_inertia, bandwidth)  # N·m/rad, N·m·s/rad
    turns_per_metre = winch.gear_ratio / (TWO_PI * winch.drum_radius)
    return AxisGains(
        bandwidth=bandwidth,
        kp=kp,
        pos_gain=kp / kd,
        vel_gain=kd * TWO_PI,
        vel_integrator_gain=0.0,
        vel_limit=VELOCITY_LIMIT_MARGIN * fastest_cable_speed(model, cable) * turns_per_metre,
        current_limit=winch.torque_limit / drives.torque_constant,
        ripple=hold_ripple(winch.rotor_inertia, kp, kd, period),
    )
