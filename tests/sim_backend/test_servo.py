"""The drives' own loops of the simulated robot (``sim_backend/servo.py``), one physics step at
a time against their laws written out here: CiA 402's interpolated PD with its clamp and its
following-error clock, ODrive's cascade with its clamp and anti-windup, and which of them a
winch's settings select."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_backend.servo import Servo, following_error_py, servo_torque

DT = 2e-4  # s: the physics step


def servo(**values: float) -> Servo:
    """One winch's loop: CiA 402's PD (kp 4 N·m/rad, kd 0.05 N·m·s/rad, 2 N·m, a 0.1 rad
    window for 3 ms) unless ``values`` say otherwise (``pos_gain`` > 0: ODrive's cascade)."""
    base = dict(target=0.0, rate=0.0, kp=4.0, kd=0.05, limit=2.0, applied=0.0, window=0.1,
                timeout=0.003, beyond=0.0, pos_gain=0.0, vel_limit=math.inf, vel_ki=0.0,
                integral=0.0)  # fmt: skip
    base.update(values)
    return Servo(**{k: np.array([float(v)]) for k, v in base.items()})


def test_the_interpolated_pd_is_its_law_and_moves_its_target_on():
    """τ = offset + kp (θ_t − θ) + kd (θ̇_t − θ̇) on the step's starting state, applied and
    returned; the target then moves on by its rate over the step."""
    s = servo(target=0.30, rate=2.0)
    tau = servo_torque(s, 0, 0.25, 1.5, 0.2, DT)
    expected = 0.2 + 4.0 * (0.30 - 0.25) + 0.05 * (2.0 - 1.5)
    assert tau == pytest.approx(expected, rel=1e-12) and s.applied[0] == tau
    assert s.target[0] == pytest.approx(0.30 + 2.0 * DT, rel=1e-12)


@pytest.mark.parametrize("error, clamped", [(10.0, 2.0), (-10.0, -2.0)])
def test_the_pd_stops_at_its_limit_both_ways(error, clamped):
    s = servo(target=error)
    assert servo_torque(s, 0, 0.0, 0.0, 0.0, DT) == clamped


def test_the_following_error_clock_runs_only_beyond_the_window():
    """Strictly beyond the window the time adds up; at the window or inside it restarts; a
    following error once the time is strictly past the time-out. The error is |θ_t − θ|:
    at θ = 1.9 against 2.0 it is 0.1, inside a 0.15 window (their product is not)."""
    s = servo(target=2.0, window=0.15, beyond=0.001)
    servo_torque(s, 0, 1.9, 0.0, 0.0, DT)
    assert s.beyond[0] == 0.0
    s = servo(target=0.5, window=0.25, beyond=0.001)
    servo_torque(s, 0, 0.25, 0.0, 0.0, DT)  # 0.25 exactly: at the window, not beyond
    assert s.beyond[0] == 0.0
    s = servo(target=0.5, window=0.2, beyond=0.001)
    servo_torque(s, 0, 0.25, 0.0, 0.0, DT)
    assert s.beyond[0] == pytest.approx(0.001 + DT)
    assert not following_error_py(servo(beyond=0.003, timeout=0.003), 0)
    assert following_error_py(servo(beyond=0.0031, timeout=0.003), 0)


@pytest.mark.parametrize("kp", [0.0, -1.0])
def test_without_a_positive_stiffness_the_drive_applies_its_offset_and_watches_nothing(kp):
    s = servo(kp=kp, target=5.0, beyond=0.002)
    assert servo_torque(s, 0, 0.0, 0.0, 0.7, DT) == 0.7
    assert s.applied[0] == 0.7 and s.beyond[0] == 0.0


def cascade(theta, theta_dot, offset, **values):
    """The cascade's law written out: (torque within the limit, velocity error)."""
    v = dict(target=0.0, rate=0.0, kd=0.05, limit=2.0, pos_gain=0.0, vel_limit=math.inf,
             integral=0.0)  # fmt: skip
    v.update(values)
    vel_des = min(v["vel_limit"], max(-v["vel_limit"],
                                      v["pos_gain"] * (v["target"] - theta) + v["rate"]))
    v_err = vel_des - theta_dot
    tau = offset + v["kd"] * v_err + v["integral"]
    return min(v["limit"], max(-v["limit"], tau)), v_err


def test_the_cascade_is_its_law_with_a_position_gain_below_one_too():
    """A position gain of 0.5 /s still selects the cascade (any positive one does): its
    torque is the law's, the integral grows by vel_ki · dt · v_err, the target is held."""
    values = dict(target=0.3, rate=0.4, kd=0.05, pos_gain=0.5, integral=0.01)
    s = servo(vel_ki=2.0, window=1e-6, beyond=0.002, **values)
    tau = servo_torque(s, 0, 0.1, 0.2, 0.1, DT)
    expected, v_err = cascade(0.1, 0.2, 0.1, **values)
    assert tau == pytest.approx(expected, rel=1e-12) and s.applied[0] == tau
    assert s.integral[0] == pytest.approx(0.01 + 2.0 * DT * v_err, rel=1e-12)
    assert s.target[0] == 0.3 and s.beyond[0] == 0.0  # held; the firmware watches no error


def test_a_negative_position_gain_is_not_a_cascade():
    s = servo(target=0.3, pos_gain=-1.0)
    tau = servo_torque(s, 0, 0.1, 0.0, 0.0, DT)
    assert tau == pytest.approx(4.0 * 0.2)  # the PD's kp (θ_t − θ)


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_the_cascade_stops_at_its_limit_both_ways_and_its_integral_decays(sign):
    s = servo(target=sign * 100.0, pos_gain=10.0, kd=0.05, limit=1.0, vel_ki=5.0, integral=0.2)
    assert servo_torque(s, 0, 0.0, 0.0, 0.0, DT) == sign * 1.0
    assert s.integral[0] == pytest.approx(0.2 * 0.99, rel=1e-12)


def test_at_exactly_its_limit_the_cascade_still_integrates():
    """offset 0.5 + kd 1 × v_err 0.5 = the 1 N·m limit: not beyond it, so the integral grows."""
    s = servo(target=0.25, pos_gain=2.0, kd=1.0, limit=1.0, vel_ki=3.0)
    assert servo_torque(s, 0, 0.0, 0.0, 0.5, DT) == 1.0
    assert s.integral[0] == pytest.approx(3.0 * DT * 0.5, rel=1e-12)
