"""Inverse/forward kinematics, wrench matrix and stiffness against independent references."""

import math

import numpy as np
import pytest
from conftest import random_poses

from cdprctl.core.rotation import exp_so3, rpy_to_matrix
from cdprctl.geometry.forward_kinematics import FKStatus, ForwardKinematics, stretched_lengths
from cdprctl.geometry.kinematics import KinematicsData, cable_lengths, inverse_kinematics
from cdprctl.geometry.stiffness import stiffness_matrix


def perturbed(p, R, dX):
    return p + dX[:3], exp_so3(dX[3:]) @ R


def central_differences(fun, h=1e-6):
    """The Jacobian of ``fun(dX)`` (a pose's 6 coordinates perturbed by dX) at dX = 0."""
    cols = []
    for j in range(6):
        dX = np.zeros(6)
        dX[j] = h
        cols.append((fun(dX) - fun(-dX)) / (2 * h))
    return np.array(cols).T


def test_ik_fk_round_trip_every_robot(robot):
    rng = np.random.default_rng(42)
    fk = ForwardKinematics(robot, tolerance=1e-13, step_tolerance=1e-12)
    for p, R in random_poses(robot, 40, rng):
        lengths = cable_lengths(robot, p, R)
        # warm start a few cm and degrees away, as after one slow control period
        p0, R0 = perturbed(p, R, rng.normal(scale=[0.02] * 3 + [0.02] * 3))
        res = fk.solve(lengths, p0, R0)
        assert res.status == FKStatus.CONVERGED, res
        np.testing.assert_allclose(res.position, p, atol=1e-8)
        np.testing.assert_allclose(res.rotation, R, atol=1e-8)
        assert res.iterations <= 6


def test_fk_from_far_start_converges(robot):
    rng = np.random.default_rng(7)
    fk = ForwardKinematics(robot)
    for p, R in random_poses(robot, 10, rng):
        lengths = cable_lengths(robot, p, R)
        res = fk.solve(lengths, robot.home.position, robot.home.rotation)
        assert res.status == FKStatus.CONVERGED
        np.testing.assert_allclose(res.position, p, atol=1e-7)


def test_fk_reports_bad_input_without_raising(seed000):
    fk = ForwardKinematics(seed000)
    lengths = np.full(8, np.nan)
    res = fk.solve(lengths, seed000.home.position, seed000.home.rotation)
    assert res.status == FKStatus.BAD_INPUT
    # impossible lengths (all 1 mm): no pose; must come back with a status, not an exception
    res = fk.solve(np.full(8, 1e-3), seed000.home.position, seed000.home.rotation)
    assert res.status != FKStatus.CONVERGED
    assert np.all(np.isfinite(res.position))


def test_wrench_matrix_is_minus_length_jacobian(robot):
    """Wᵀ = −∂l/∂X by central finite differences (pulleys included: the wrapped arc)."""
    data = KinematicsData(robot)
    for p, R in random_poses(robot, 8, np.random.default_rng(3)):
        inverse_kinematics(robot, data, p, R)
        WT = data.WT.copy()
        J = central_differences(lambda dX, p=p, R=R: cable_lengths(robot, *perturbed(p, R, dX)))
        np.testing.assert_allclose(WT, -J, atol=2e-8)


def test_stiffness_matches_finite_differences_of_cable_wrench(robot):
    """K = −∂(W t)/∂X with t = t0 + diag(k)(l − l0): winches locked, Picard et al. eq. (3)."""
    if robot.has_pulleys:
        pytest.skip("Ka neglects the tangent point's motion on the pulley (documented)")
    rng = np.random.default_rng(4)
    data = KinematicsData(robot)
    for p, R in random_poses(robot, 5, rng):
        inverse_kinematics(robot, data, p, R)
        l0 = data.length.copy()
        k = robot.cable_stiffness(l0)
        t0 = rng.uniform(robot.tension_min, robot.tension_max)
        K = stiffness_matrix(robot, data, t0, k)

        def cable_wrench(dX, p=p, R=R, t0=t0, k=k, l0=l0):
            d = KinematicsData(robot)
            inverse_kinematics(robot, d, *perturbed(p, R, dX))
            return d.W @ (t0 + k * (d.length - l0))

        K_fd = -central_differences(cable_wrench)
        scale = np.abs(K_fd).max()
        np.testing.assert_allclose(K, K_fd, atol=1e-6 * scale)


def test_passive_stiffness_is_symmetric_positive_definite(rowc):
    data = KinematicsData(rowc)
    inverse_kinematics(rowc, data, rowc.home.position, rowc.home.rotation)
    K = stiffness_matrix(rowc, data, np.zeros(8))
    np.testing.assert_allclose(K, K.T, rtol=1e-12, atol=1e-9)
    assert np.linalg.eigvalsh(K).min() > 0


def test_seed000_wrench_matrix_balances_table2(seed000, seed000_expected):
    """Sensors 2019 Table 2 tensions hold Fext = (200, 0, −1470 | −0.5, 0, 0) at the roll pose."""
    W = np.array(
        __import__("cdprctl.geometry.kinematics", fromlist=["wrench_matrix"]).wrench_matrix(
            seed000, seed000.home.position, seed000.home.rotation
        )
    )
    f_ext = np.array([200.0, 0.0, -1470.0, -0.5, 0.0, 0.0])
    for tau in seed000_expected["table2"]["paper_tau"]:
        residual = W @ np.array(tau) + f_ext
        assert np.abs(residual[:3]).max() < 0.12  # N: the table prints 0.1 N
        assert np.abs(residual[3:]).max() < 0.06  # N·m


def test_seed000_home_attachments_match_reconstruction(seed000):
    import json

    from conftest import ROOT

    ref = json.loads((ROOT / "tests" / "data" / "seed000.json").read_text())
    data = KinematicsData(seed000)
    inverse_kinematics(seed000, data, seed000.home.position, seed000.home.rotation)
    np.testing.assert_allclose(data.attach_points, ref["platform_attachments_world_m"], atol=1e-6)
    np.testing.assert_allclose(
        seed000.home.rotation, ref["pose"]["rotation_matrix_used"], atol=1e-12
    )


def test_pulley_exit_point_is_a_tangent_point():
    """Geometric invariants of the swivel-pulley model: the exit point lies on the wheel, in the
    plane of the swivel axis and B, the free cable is tangent to the wheel there, and the wrapped
    arc joins the entry point (on the axis) to it over the side facing the winch's cable."""
    from conftest import CONFIG

    from cdprctl.robot_file import load_robot

    model = load_robot(CONFIG / "caroca_pulleys.toml")
    rng = np.random.default_rng(5)
    data = KinematicsData(model)
    for p, R in random_poses(model, 5, rng):
        inverse_kinematics(model, data, p, R)
        for i, c in enumerate(model.cables):
            a, z, r = c.anchor, c.pulley.axis, c.pulley.radius
            B, T = data.attach_points[i], data.exit_points[i]
            d = B - a
            e = d - (d @ z) * z
            e /= np.linalg.norm(e)
            C = a + r * e
            assert np.linalg.norm(T - C) == pytest.approx(r, abs=1e-12)
            n = np.cross(e, z)
            assert abs((T - a) @ n) < 1e-12  # in the swivel plane
            assert abs((T - C) @ (B - T)) < 1e-10  # tangent
            # polar angle of T about C from e towards z; the arc from the entry point (angle π)
            phi = math.atan2((T - C) @ z, (T - C) @ e)
            assert data.wrap_angle[i] == pytest.approx(math.pi - phi, abs=1e-12)
            assert data.length[i] == pytest.approx(
                r * (math.pi - phi) + np.linalg.norm(B - T), abs=1e-12
            )
            # pulleys on top of the frame, platform below: between a quarter and half a turn
            assert math.pi / 2 < data.wrap_angle[i] < math.pi


def test_stretched_lengths_round_trip(rowc):
    """A cable of E·S under tension t stretches by t·l0/(E·S): inverse of the unstretched length."""
    lengths = cable_lengths(rowc, rowc.home.position, rowc.home.rotation)
    t = np.linspace(10, 200, 8)
    es = 80e9 * 0.75e-6
    l0 = lengths / (1 + t / es)
    np.testing.assert_allclose(stretched_lengths(rowc, l0, t), lengths, rtol=1e-14)


def test_rpy_pose_of_rowc_home():
    np.testing.assert_allclose(rpy_to_matrix(0, 0, 0), np.eye(3))


def test_weighted_active_stiffness_equals_per_cable_sum(robot):
    """The summed closed form used by SOTDA equals Σ t_i Ka_i from eq. (4) cable by cable."""
    from cdprctl.geometry.stiffness import active_stiffness_per_cable, active_stiffness_weighted

    rng = np.random.default_rng(21)
    data = KinematicsData(robot)
    for p, R in random_poses(robot, 4, rng):
        inverse_kinematics(robot, data, p, R)
        T = rng.uniform(0, 500, size=(3, robot.n_cables))
        per = active_stiffness_per_cable(data)
        ref = np.einsum("nm,mij->nij", T, per)
        np.testing.assert_allclose(
            active_stiffness_weighted(data, T), ref, atol=1e-9 * np.abs(ref).max()
        )
