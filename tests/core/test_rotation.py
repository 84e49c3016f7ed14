import math

import numpy as np
import pytest

from cdprctl.core.rotation import (
    exp_so3,
    log_so3,
    matrix_to_rpy,
    rot_x,
    rot_y,
    rot_z,
    rpy_to_matrix,
    skew,
)


def test_rpy_is_fixed_axis_xyz():
    r, p, y = 0.3, -0.4, 1.1
    np.testing.assert_allclose(rpy_to_matrix(r, p, y), rot_z(y) @ rot_y(p) @ rot_x(r), atol=1e-15)


def test_rpy_round_trip():
    rng = np.random.default_rng(1)
    for _ in range(200):
        rpy = rng.uniform([-math.pi, -1.5, -math.pi], [math.pi, 1.5, math.pi])
        R = rpy_to_matrix(*rpy)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_allclose(matrix_to_rpy(R), rpy, atol=1e-12)


def test_exp_log_round_trip_and_small_angles():
    rng = np.random.default_rng(2)
    for scale in (1e-12, 1e-6, 0.5, 3.0):
        for _ in range(50):
            phi = rng.normal(size=3)
            phi *= scale / np.linalg.norm(phi)
            R = exp_so3(phi)
            np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-14)
            np.testing.assert_allclose(log_so3(R), phi, atol=1e-10 * max(1.0, scale))


def test_exp_matches_axis_rotation():
    np.testing.assert_allclose(exp_so3(np.array([0.0, 0.0, 0.7])), rot_z(0.7), atol=1e-15)


def test_skew_is_cross_product():
    a, b = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.2, -4.0])
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b))


@pytest.mark.parametrize("pitch", [math.pi / 2, -math.pi / 2])
def test_at_gimbal_lock_the_angles_given_back_make_the_same_rotation(pitch):
    """At pitch ±90° only roll ± yaw is defined: the angles returned may differ from those
    given, the rotation they make may not (the record's and the telemetry's pose)."""
    for roll, yaw in [(0.0, 0.3), (0.4, -1.1), (-2.0, 2.5)]:
        R = rpy_to_matrix(roll, pitch, yaw)
        np.testing.assert_allclose(rpy_to_matrix(*matrix_to_rpy(R)), R, atol=1e-9)
