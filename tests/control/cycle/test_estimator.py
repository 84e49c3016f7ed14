"""The pose estimator: forward kinematics on the encoder lengths, feedback of mixed ages brought
to one instant, velocity against the known motion (the truth comes from inverse kinematics)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.control.cycle.estimator import Estimator
from cdprctl.geometry.kinematics import cable_lengths
from cdprctl.robot_file import load_robot


@pytest.fixture(scope="module")
def rowc():
    return load_robot(CONFIG / "rowc.toml")


def motor_angles(est: Estimator, model, position) -> np.ndarray:
    """Encoder angles (rad) of unloaded cables at ``position`` (home orientation): the inverse
    of ``l0 = l_home − (r/G) θ``."""
    lengths = cable_lengths(model, np.asarray(position), model.home.rotation)
    return (est.l_home - lengths) / est.drum_ratio


def test_a_late_drive_does_not_make_a_velocity_spike(rowc):
    """Platform moving at 0.3 m/s along x, read every 4 ms; cable 3's feedback is one period
    late in every third read (a lost or late frame on the bus). With the ages given, the pose
    and the velocity stay on the truth; the read-time finite difference of the past spiked."""
    h, speed = 0.004, np.array([0.3, 0.0, 0.0])
    p0 = np.array(rowc.home.position)
    zero = np.zeros(rowc.n_cables)
    est, naive = Estimator(rowc), Estimator(rowc)
    for e in (est, naive):
        e.reset(p0, rowc.home.rotation)
    worst_aligned, worst_naive, worst_pose = 0.0, 0.0, 0.0
    for k in range(1, 100):
        t = k * h
        sample = t - h  # the SYNC instant the fresh feedback belongs to
        theta = motor_angles(est, rowc, p0 + speed * sample)
        rate = (motor_angles(est, rowc, p0 + speed * (sample + 1e-6)) - theta) / 1e-6
        age = np.full(rowc.n_cables, h)
        if k % 3 == 0:
            theta[3] = motor_angles(est, rowc, p0 + speed * (sample - h))[3]
            age[3] = 2 * h
        est.update(t, theta, zero, rate, age)
        naive.update(t, theta, zero)
        if k > 40:  # past the filter's start transient
            worst_aligned = max(worst_aligned, float(np.linalg.norm(est.velocity - speed)))
            worst_naive = max(worst_naive, float(np.linalg.norm(naive.velocity - speed)))
            truth = p0 + speed * sample
            worst_pose = max(worst_pose, float(np.linalg.norm(est.position - truth)))
    assert worst_pose < 1e-6  # m
    assert worst_aligned < 1e-3  # m/s
    assert worst_naive > 0.05  # m/s: what the alignment removes


def test_velocity_filter_follows_a_step_in_speed(rowc):
    """First-order low-pass: after one time constant 1/(2π f_c), 63 % of a speed step."""
    est = Estimator(rowc)
    p0 = np.array(rowc.home.position)
    est.reset(p0, rowc.home.rotation)
    zero = np.zeros(rowc.n_cables)
    h, v = 0.001, 0.1
    tau = 1.0 / (2 * np.pi * rowc.control.velocity_filter)
    est.update(0.0, motor_angles(est, rowc, p0), zero)
    n = round(tau / h)
    for k in range(1, n + 1):
        est.update(k * h, motor_angles(est, rowc, p0 + np.array([v * k * h, 0.0, 0.0])), zero)
    assert est.velocity[0] / v == pytest.approx(1 - np.exp(-n * h / tau), abs=2e-3)
