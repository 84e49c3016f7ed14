"""An ODrive axis's position-mode settings from the robot's model: its cascaded loops' gains,
its velocity limit and its current limit, in the units ODrive's CAN Simple messages carry.

ODrive's position mode is a cascade (docs.odriverobotics.com, "Control Structure and Tuning";
firmware ``Controller::update``): ``vel_des = pos_gain (pos_setpoint − pos) + vel_ff``, clamped
to ``vel_limit``; ``torque = vel_gain (vel_des − vel) + integrator + torque_ff``. Without the
integrator and the clamp it is the CiA 402 drives' loop ``kp (θ_t − θ) + kd (θ̇_t − θ̇)``
(``DrivesConfig.position_gains``: the rotor at ``position_loop_bandwidth``, damping 0.7) with
``vel_gain = kd`` and ``pos_gain = kp / kd``: one rule for both protocols, with one bound.
A CiA 402 drive interpolates its targets between SYNCs; an ODrive in passthrough holds each
Set_Input_Pos for a period, a staircase its loop follows step by step when it is fast beside
the rate: its torque then swings by ``kp · rate · T / 2`` within every period (1 N·m on rowc
at 0.3 m/s and 50 Hz: 100 N of cable), read as tension. So its loop sits a decade below the
control rate (``STEPS_PER_LOOP``), as the working pose sits a decade below the drives' loops.
rowc at 250 Hz, lock-step, its demo's moves: tracking 1.1 mm RMS with the loop at 50 Hz,
0.10 mm at 25 Hz, 0.05 mm at 12.5 Hz; the 30 N jet's transient 6.5, 8.4 and 17.2 mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

TWO_PI = 2.0 * math.pi
# the velocity limit over the fastest cable speed a planned motion asks for: room for the
# pose loop's corrections and a disturbance's ride-through; ODrive's overspeed error trips at
# its vel_limit_tolerance (1.2 by default) times the limit
VELOCITY_LIMIT_MARGIN = 2.0
# control periods per period of the axis's position loop, at the least
STEPS_PER_LOOP = 10.0


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


def loop_bandwidth(model: Any, period: float) -> float:
    """Hz: ``[drives] position_loop_bandwidth``, at most a decade below the control rate."""
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
    )
