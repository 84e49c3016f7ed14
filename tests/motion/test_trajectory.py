"""The jerk-limited trajectory (motion/trajectory.py, ruckig), table-driven: every move ends on
its (clamped) target, and the finite differences of the sampled reference respect the velocity,
acceleration and jerk limits (scaled by the command's fractions), including a new target taken
mid-motion and a stop."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cdprctl.motion.trajectory import Trajectory
from cdprctl.robot_file import load_robot

ROOT = Path(__file__).resolve().parents[2]
ROWC = load_robot(ROOT / "config" / "rowc.toml")
C = ROWC.control
HOME = np.concatenate([ROWC.home.position, np.zeros(3)])
VEL = np.array([C.max_velocity] * 3 + [C.max_angular_velocity] * 3)
ACC = np.array([C.max_acceleration] * 3 + [C.max_angular_acceleration] * 3)
JERK = np.array([C.max_jerk] * 3 + [C.max_angular_jerk] * 3)


def run(tr: Trajectory, seconds: float, switch=None) -> np.ndarray:
    """The reference sampled every period for ``seconds``; ``switch(tr, k)`` before cycle k."""
    out = []
    for k in range(round(seconds / tr.otg.delta_time)):
        if switch is not None:
            switch(tr, k)
        tr.update()
        out.append(tr.position.copy())
    return np.array(out)


def check_limits(x: np.ndarray, dt: float, speed: float, accel: float) -> None:
    """Finite differences of the samples against the limits (a 2 % margin for the
    differences' own error)."""
    v = np.diff(x, axis=0) / dt
    a = np.diff(v, axis=0) / dt
    j = np.diff(a, axis=0) / dt
    assert np.all(np.abs(v) <= 1.02 * VEL * speed + 1e-9)
    assert np.all(np.abs(a) <= 1.02 * ACC * accel + 1e-6)
    assert np.all(np.abs(j) <= 1.02 * JERK + 1e-3)


# (name, target offset from home: x y z (m), rotation vector (rad); speed, accel fraction)
MOVES = [
    ("along x", [0.4, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0, 1.0),
    ("diagonal, slow", [-0.5, 0.02, -0.1, 0.0, 0.0, 0.0], 0.3, 0.5),
    ("a rotation", [0.0, 0.0, 0.0, 0.0, 0.0, 0.1], 1.0, 1.0),
    ("position and rotation", [0.2, -0.01, 0.05, 0.05, -0.05, 0.1], 0.5, 1.0),
    ("a short hop", [0.001, 0.0, 0.0, 0.0, 0.0, 0.0], 1.0, 1.0),
]


@pytest.mark.parametrize("name,offset,speed,accel", MOVES, ids=[m[0] for m in MOVES])
def test_a_move_ends_on_target_within_the_limits(name, offset, speed, accel):
    tr = Trajectory(ROWC, C.period)
    tr.reset(HOME)
    target = HOME + np.array(offset)
    tr.set_target(target, speed, accel)
    x = run(tr, 12.0)
    assert tr.finished
    np.testing.assert_allclose(x[-1], target, atol=1e-9)
    np.testing.assert_allclose(tr.velocity, 0.0, atol=1e-9)
    check_limits(np.vstack([HOME, x]), C.period, speed, accel)
    # phase-synchronised: a straight line in the position coordinates
    d = offset[:3]
    if np.linalg.norm(d) > 0:
        u = np.asarray(d) / np.linalg.norm(d)
        rel = x[:, :3] - HOME[:3]
        assert np.abs(rel - np.outer(rel @ u, u)).max() < 1e-6


def test_targets_are_clamped_to_the_workspace():
    tr = Trajectory(ROWC, C.period)
    tr.reset(HOME)
    ws = ROWC.workspace
    tr.set_target(np.array([10.0, -3.0, 0.5, 0.0, 0.0, 1.0]))
    np.testing.assert_allclose(tr.target[:3], [ws.position_max[0], ws.position_min[1], 0.5])
    assert np.linalg.norm(tr.target[3:]) == pytest.approx(ws.max_angle)


def test_a_new_target_mid_motion_is_continuous():
    tr = Trajectory(ROWC, C.period)
    tr.reset(HOME)
    tr.set_target(HOME + np.array([0.5, 0, 0, 0, 0, 0]))
    back = HOME + np.array([-0.3, 0.0, -0.1, 0.0, 0.0, 0.0])

    def switch(t: Trajectory, k: int) -> None:
        if k == 400:  # 0.8 s in, at speed
            t.set_target(back)

    x = run(tr, 15.0, switch)
    np.testing.assert_allclose(x[-1], back, atol=1e-9)
    check_limits(np.vstack([HOME, x]), C.period, 1.0, 1.0)


def test_a_stop_decelerates_to_rest_within_the_limits():
    tr = Trajectory(ROWC, C.period)
    tr.reset(HOME)
    tr.set_target(HOME + np.array([0.8, 0, 0, 0, 0, 0]))

    def switch(t: Trajectory, k: int) -> None:
        if k == 500:
            t.stop_here()

    x = run(tr, 4.0, switch)
    assert tr.finished
    np.testing.assert_allclose(tr.velocity, 0.0, atol=1e-9)
    assert HOME[0] < x[-1, 0] < HOME[0] + 0.8  # stopped short of the target
    check_limits(np.vstack([HOME, x]), C.period, 1.0, 1.0)


def run_to_rest(tr: Trajectory, cycles: int = 20000) -> tuple[float, float, int]:
    """Update until finished: (peak |velocity|, peak |acceleration| along x, cycles)."""
    v = a = 0.0
    for n in range(cycles):
        tr.update()
        v, a = max(v, abs(tr.velocity[0])), max(a, abs(tr.acceleration[0]))
        if tr.finished:
            return v, a, n + 1
    raise AssertionError("the trajectory never finished")


def test_a_speed_or_acceleration_scale_above_one_gives_the_configured_limits():
    """The scales only slow a move down: 3 is 1 (a command's scale is also checked at the
    gateway; this is the second line)."""
    tr = Trajectory(ROWC, C.period)
    tr.reset(HOME)
    tr.set_target(HOME + np.array([0.6, 0, 0, 0, 0, 0]), speed_scale=3.0, accel_scale=3.0)
    v, a, _ = run_to_rest(tr)
    assert v <= tr.limits[0] * (1 + 1e-9) and a <= tr.acc_limits[0] * (1 + 1e-9)
    assert v > 0.99 * tr.limits[0]  # it did reach its limit


def test_a_stop_brakes_at_the_full_acceleration_whatever_the_moves_scale():
    """A move at a tenth of the acceleration, stopped at speed: the stop (stop, pause, abort,
    the controlled stop) brakes at the configured acceleration, well within half the distance
    the move's own tenth would need."""
    tr = Trajectory(ROWC, C.period)
    tr.reset(HOME)
    tr.set_target(HOME + np.array([0.8, 0, 0, 0, 0, 0]), accel_scale=0.1)
    for _ in range(400):
        tr.update()
    x, v = float(tr.position[0]), float(tr.velocity[0])
    assert v > 0.1  # m/s: still speeding up
    tr.stop_here()
    _, a, _ = run_to_rest(tr)
    slow = v * v / (2 * 0.1 * tr.acc_limits[0])  # m: braking at the move's tenth
    assert float(tr.position[0]) - x < 0.5 * slow
    assert a > 0.5 * tr.acc_limits[0]
