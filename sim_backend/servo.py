"""The drives' own position loops, run inside the physics step: a CiA 402 drive's cyclic
synchronous position (a PD around a target interpolated between SYNCs, with its following-error
supervision) and an ODrive axis's cascade in passthrough (position P into velocity PI). The
simulated drives set them (``sim_backend/drives``); ``physics.physics_kernel`` calls
``servo_torque`` for each winch in position mode."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit


class Servo(NamedTuple):
    """The drives' own position loops (CiA 402 cyclic synchronous position, per winch): the
    interpolated target (rad) and its rate (rad/s), the gains (N·m/rad, 0 = torque mode;
    N·m·s/rad), the torque limit (N·m), the torque applied in the last step (N·m, out), the
    following error window (rad, CiA 402 0x6065; inf: not monitored), its time-out (s, 0x6066)
    and how long the error has been beyond the window without a break (s, out): past the
    time-out the drive's firmware brakes within the physics step (``following_error``), its
    state machine faults at its next tick.
    An ODrive's cascade instead where ``pos_gain`` (1/s) is positive: the position P loop
    into the velocity loop (``kd`` its gain), ``vel_limit`` (rad/s) clamping the velocity it
    asks for, the velocity integrator's gain ``vel_ki`` (N·m/rad) and its torque ``integral``
    (N·m, state); ``rate`` there is the velocity feed-forward, ``target`` held as sent.
    The torque offset is ``Inputs.motor_torque``."""

    target: np.ndarray
    rate: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    limit: np.ndarray
    applied: np.ndarray
    window: np.ndarray
    timeout: np.ndarray
    beyond: np.ndarray
    pos_gain: np.ndarray
    vel_limit: np.ndarray
    vel_ki: np.ndarray
    integral: np.ndarray


@njit(cache=True)
def servo_torque(servo, i, theta, theta_dot, offset, dt):  # pragma: no cover - compiled
    """N·m the drive of winch ``i`` applies this physics step: in position mode its loop
    ``offset + kp (θ_t − θ) + kd (θ̇_t − θ̇)`` within its limit, the target moving at the
    interpolation rate (set at each SYNC to reach the new target one SYNC later, and kept
    beyond it while a SYNC is late: linear interpolation and extrapolation, as CSP drives
    do; ``Cia402Drive`` holds it after ``extrapolate_for``); in torque mode ``offset``. No
    integral: with one on all eight winches of rowc the platform's y mode (~3 Hz) grew from
    0.5 to 9 mrad of motor error in 2 s at constant targets (lock-step, measured); the torque
    offset carries the load instead."""
    target, rate, kp, kd, limit, applied, window, _, beyond, pos_gain, _, _, _ = servo
    if kp[i] <= 0.0:
        applied[i] = offset
        beyond[i] = 0.0
        return offset
    if pos_gain[i] > 0.0:
        return _cascade_torque(servo, i, theta, theta_dot, offset, dt)
    # the loop on the step's starting state: with the target moved on first, the torque
    # carried kp · rate · dt, a term of the step's length (0.2 N·m at 50 rad/s), and the
    # torque actual sampled from a short last step before a SYNC read tens of newtons less
    tau = offset + kp[i] * (target[i] - theta) + kd[i] * (rate[i] - theta_dot)
    tau = min(limit[i], max(-limit[i], tau))
    target[i] += rate[i] * dt
    if abs(target[i] - theta) > window[i]:
        beyond[i] += dt
    else:
        beyond[i] = 0.0
    applied[i] = tau
    return tau


@njit(cache=True)
def _cascade_torque(servo, i, theta, theta_dot, offset, dt):  # pragma: no cover - compiled
    """N·m an ODrive axis in position control applies this physics step, as its firmware's
    ``Controller::update`` does with the input mode passthrough (docs.odriverobotics.com,
    "Control Structure and Tuning"): ``vel_des = pos_gain (pos_setpoint − pos) + vel_ff``
    clamped to ``±vel_limit``; ``torque = torque_ff + vel_gain (vel_des − vel) + integral``
    clamped to the limit; the integral grows by ``vel_integrator_gain · dt · v_err``, or
    decays by 0.99 a step while the torque is limited (its anti-windup). The firmware runs
    this at 8 kHz, here at the physics step (5 kHz as shipped)."""
    target, rate, _, kd, limit, applied, _, _, beyond, pos_gain, vel_limit, vel_ki, integral = (
        servo
    )
    vel_des = pos_gain[i] * (target[i] - theta) + rate[i]
    vel_des = min(vel_limit[i], max(-vel_limit[i], vel_des))
    v_err = vel_des - theta_dot
    tau = offset + kd[i] * v_err + integral[i]
    if abs(tau) > limit[i]:
        tau = min(limit[i], max(-limit[i], tau))
        integral[i] *= 0.99
    else:
        integral[i] += vel_ki[i] * dt * v_err
    beyond[i] = 0.0  # no following-error supervision in the firmware
    applied[i] = tau
    return tau


def _following_error(servo, i):
    """True once winch ``i``'s position error has been beyond its window past the time-out."""
    return servo[8][i] > servo[7][i]


following_error = njit(cache=True)(_following_error)
following_error_py = _following_error  # the same rule for the drives' Python side
