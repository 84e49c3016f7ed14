"""The self-calibration's least squares (``cdprctl.calibration.identify``) against references
it does not compute itself: samples built from the model's kinematics and cable law at known
poses, a finite-difference Jacobian, the equilibrium written out cable by cable, a
Monte-Carlo quantization, the robot files' own numbers. Unit level and fast: the closed loop
on the simulated robot is in test_homing.py."""

from __future__ import annotations

import dataclasses
import math
import tomllib

import numpy as np
import pytest
from conftest import CONFIG
from scipy.spatial.transform import Rotation

from cdprctl.calibration.identify import (
    Identification,
    Samples,
    Weights,
    length_noise,
    model_test,
    quantization_std,
)
from cdprctl.calibration.procedure import SelfOptions, sample_poses
from cdprctl.core.numerics import compliance_of, unstretched_lengths
from cdprctl.core.rotation import exp_so3
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.robot_file import load_robot
from cdprctl.tda.hold import equilibrium_tensions

# a solve that warns (a tolerance that disables its own test, a singular matrix inverted)
# is a solve gone wrong
pytestmark = pytest.mark.filterwarnings("error")


@dataclasses.dataclass
class Truth:
    poses: np.ndarray  # K × 6: position (m), rotation vector from home (rad)
    scale: np.ndarray  # per drum
    theta_home: np.ndarray  # rad, in the samples' angles: where the unstretched length is home's


def ratio_of(model):
    return np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])


def synthetic(model, rng=None, K=None):
    """Samples at x0 + the self-calibration's moves, computed from the model's kinematics and
    cable law with drum scales off by up to ±0.4 %; with ``rng``, seeded noise of the
    weights' σ on the angles (the length σ through the drum) and the tensions."""
    law = compliance_of(model.cables)
    ratio = ratio_of(model)
    kin = KinematicsData(model)
    x0 = np.r_[np.add(model.home.position, [0.03, -0.01, 0.04]), 0.02, -0.03, 0.01]
    scale = 1.0 + np.linspace(-0.004, 0.004, model.n_cables)
    guess = sample_poses(model, SelfOptions())[:K]
    poses = x0 + (guess - guess[0])
    theta, tension = [], []
    for x in poses:
        inverse_kinematics(model, kin, x[:3], exp_so3(x[3:]) @ model.home.rotation)
        t = equilibrium_tensions(model, kin)
        theta.append(-unstretched_lengths(law, kin.length, t) / (ratio * scale))
        tension.append(t)
    theta, tension = np.array(theta), np.array(tension)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    theta_home = -kin.length / (ratio * scale) - theta[0]
    theta = theta - theta[0]
    if rng is not None:
        w = Weights.of(model)
        theta = theta + rng.normal(scale=w.length / ratio, size=theta.shape)
        tension = tension + rng.normal(scale=w.tension, size=tension.shape)
    return Samples(theta, tension, guess), Truth(poses, scale, theta_home)


def fd_jacobian(ident, z, s, h=1e-7):
    """Central differences of the weighted residuals."""
    cols = []
    for j in range(z.size):
        e = np.zeros_like(z)
        e[j] = h
        cols.append((ident.residuals(z + e, s) - ident.residuals(z - e, s)) / (2 * h))
    return np.array(cols).T


def closures_and_wrenches(model, poses, s, scales):
    """m and N, N·m, written out cable by cable (not through ``KinematicsData.W``): every
    sample's length closure (stretched length of its unstretched length at its tension
    against the geometric one) and the wrench its tensions and gravity leave."""
    law = compliance_of(model.cables)
    ratio = ratio_of(model)
    assert all(c.spring_stiffness is None and c.stiffness is None for c in model.cables)
    youngs = np.array([c.youngs_modulus for c in model.cables])  # Pa
    section = np.array([c.cross_section for c in model.cables])  # m²
    closures, wrenches = [], []
    for k, x in enumerate(poses):
        R = exp_so3(x[3:]) @ model.home.rotation
        L, wrench = np.zeros(model.n_cables), np.zeros(6)
        for i, c in enumerate(model.cables):
            arm = R @ np.asarray(c.attachment)
            v = np.asarray(c.anchor) - (x[:3] + arm)
            L[i] = np.linalg.norm(v)
            f = s.tension[k, i] * v / L[i]
            wrench += np.r_[f, np.cross(arm, f)]
        weight = model.platform.mass * np.asarray(model.gravity)
        wrench += np.r_[weight, np.cross(R @ np.asarray(model.platform.com), weight)]
        wrenches.append(wrench)
        if k == 0:
            l0_start = unstretched_lengths(law, L, s.tension[0])
        else:  # the unstretched length the drum paid out against the one the geometry
            # asks at that tension, in length: a plain E·S cable stretches by 1 + t/(E·S)
            l0 = l0_start - ratio * scales * (s.theta[k] - s.theta[0])
            stretch = 1.0 + s.tension[k] / (youngs * section)
            closures.append((unstretched_lengths(law, L, s.tension[k]) - l0) * stretch)
    return np.array(closures), np.array(wrenches)


@pytest.fixture(scope="module")
def rowc():
    return load_robot(CONFIG / "rowc.toml")


def test_the_sparsity_is_the_finite_difference_jacobians_pattern(rowc):
    """Every residual depends on exactly the unknowns the sparsity declares: a missed one
    would be a column least squares never differentiates, an extra one costs evaluations."""
    s, _ = synthetic(rowc, K=4)
    rng = np.random.default_rng(5)
    for fit in (False, True):
        ident = Identification(rowc, fit)
        z = np.r_[s.guess.ravel() + rng.normal(scale=1e-3, size=24), np.ones(8) if fit else []]
        pattern = fd_jacobian(ident, z, s, h=1e-6) != 0.0
        declared = ident._sparsity(4).toarray() != 0
        assert declared.shape == pattern.shape == (6 + 3 * (8 + 6), 24 + (8 if fit else 0))
        np.testing.assert_array_equal(declared, pattern)


def test_noise_free_samples_give_the_start_the_scales_and_the_zero_angles_to_rounding(rowc):
    s, truth = synthetic(rowc)
    got = Identification(rowc, True).solve(s)
    assert got.success, got.message
    np.testing.assert_allclose(got.poses, truth.poses, atol=1e-10)
    np.testing.assert_allclose(got.drum_scale, truth.scale, atol=1e-10)
    np.testing.assert_allclose(got.theta_zero, truth.theta_home, atol=1e-8)  # rad at the motor
    rpy = Rotation.from_matrix(exp_so3(truth.poses[0, 3:]) @ rowc.home.rotation).as_euler("xyz")
    np.testing.assert_allclose(got.pose, np.r_[truth.poses[0, :3], rpy], atol=1e-10)
    assert got.residual_rms < 1e-12 and got.force_rms < 1e-9 and got.variance_factor < 1e-12


def test_noisy_samples_report_their_residuals_spread_and_condition(rowc):
    """Tension and angle noise of the weights' σ (seeded): the reported closures and wrenches
    are the ones written out at the identified poses; the variance factor is about 1 (the
    weights are the noise's); the predicted σ and the condition are those of the
    finite-difference Jacobian, the variance factor floored at a tenth."""
    K, m = 13, rowc.n_cables
    s, _ = synthetic(rowc, np.random.default_rng(8))
    ident = Identification(rowc, True)
    got = ident.solve(s)  # (not converged to 1e-12 in 200 evaluations: the noise's minimum is flat)
    assert got.dof == (K - 1) * m + 6 * K - (6 * K + m)
    closures, wrenches = closures_and_wrenches(rowc, got.poses, s, got.drum_scale)
    np.testing.assert_allclose(got.length_residuals, closures.ravel(), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(got.residual_rms, np.sqrt(np.mean(closures**2)), rtol=1e-6)
    each = np.sqrt(np.mean(closures**2, axis=1))
    np.testing.assert_allclose(got.sample_residuals, np.r_[0.0, each], rtol=1e-6)
    np.testing.assert_allclose(got.force_rms, np.sqrt(np.mean(wrenches**2)), rtol=1e-6)
    assert 0.6 < got.variance_factor < 1.5, got.variance_factor
    z = np.r_[got.poses.ravel(), got.drum_scale]
    r = ident.residuals(z, s)
    assert got.variance_factor == pytest.approx(float(r @ r) / got.dof, rel=1e-9)
    J = fd_jacobian(ident, z, s)
    normalised = J / np.linalg.norm(J, axis=0)
    np.testing.assert_allclose(got.condition, np.linalg.cond(normalised), rtol=1e-3)
    predicted = np.sqrt(np.diag(np.linalg.inv(J.T @ J))[:6] * got.variance_factor)
    np.testing.assert_allclose(got.std, predicted, rtol=1e-3)


def test_a_noise_free_fit_predicts_the_spread_of_a_tenth_of_the_noise_not_zero(rowc):
    """The variance factor of exact samples is ~0: the predicted σ is floored at a tenth of
    it (a few lucky samples do not make the pose exact)."""
    s, _ = synthetic(rowc)
    ident = Identification(rowc, True)
    got = ident.solve(s)
    J = fd_jacobian(ident, np.r_[got.poses.ravel(), got.drum_scale], s)
    predicted = np.sqrt(np.diag(np.linalg.inv(J.T @ J))[:6] * 0.1)
    assert len(got.std) == 6
    np.testing.assert_allclose(got.std, predicted, rtol=1e-3)


def test_one_sample_is_the_equilibrium_alone_and_a_drum_it_never_turned_is_unknown(rowc):
    """K = 1: no length closure; the tensions alone decide the pose (6 equations, 6
    unknowns: one degree of freedom counted, not zero); with drum scales to fit, they are
    columns nothing sees: infinitely ill-conditioned, the σ infinite, said so."""
    s, truth = synthetic(rowc, K=1)
    got = Identification(rowc, False).solve(s)
    assert got.success, got.message
    np.testing.assert_allclose(got.poses[0], truth.poses[0], atol=1e-8)
    assert got.dof == 1 and got.length_residuals.shape == (0,)
    assert got.residual_rms == 0.0 and got.sample_residuals == [0.0]
    assert math.isfinite(got.condition) and all(map(math.isfinite, got.std))
    scaled = Identification(rowc, True).solve(s)
    assert scaled.condition == math.inf
    assert scaled.std == [math.inf] * 6


def test_the_weights_are_one_count_of_the_drives_resolution_from_the_robot_files():
    """σ_t: one count of 0x6077 (a thousandth of the rated torque) through the drum, at
    least 1 N; σ_L: the stretch of that tension on the softest cable at home plus one
    encoder count through the drum — from the TOML's numbers, stiffness E·S/L."""
    for name, tension in (("rowc", 1.0), ("caroca", 2.0)):  # rowc: 0.29 N, floored
        raw = tomllib.loads((CONFIG / f"{name}.toml").read_text())
        model = load_robot(CONFIG / f"{name}.toml")
        drum, gear = raw["winch"]["drum_radius"], raw["winch"]["gear_ratio"]
        count_tension = model.drives.rated_torque / 1000.0 * gear / drum
        assert max(1.0, count_tension) == pytest.approx(tension)
        home = np.asarray(raw["home"]["position"])  # both files: home orientation level
        assert raw["home"]["rpy"] == [0.0, 0.0, 0.0]
        compliance = max(
            np.linalg.norm(np.subtract(c["anchor"], home + c["attachment"]))
            / (c["youngs_modulus"] * c["cross_section"])
            for c in raw["cables"]
        )
        count = 2.0 * math.pi / raw["winch"]["encoder_counts_per_rev"] * drum / gear
        w = Weights.of(model)
        assert w.tension == pytest.approx(tension, rel=1e-12)
        assert w.length == pytest.approx(compliance * tension + count, rel=1e-9)
        with pytest.raises(dataclasses.FrozenInstanceError):
            w.length = 1.0  # type: ignore[misc]


def test_the_moment_weight_is_the_force_weight_over_the_platforms_reach(rowc):
    ident = Identification(rowc, True)
    reach = max(math.hypot(*c.attachment) for c in rowc.cables)  # m
    sigma_f = ident.w.tension * math.sqrt(rowc.n_cables)  # N
    np.testing.assert_allclose(
        ident.force_weight, [1 / sigma_f] * 3 + [1 / (sigma_f * reach)] * 3, rtol=1e-12
    )


def test_a_length_closures_noise_is_the_quantization_of_one_step():
    """Monte Carlo (seeded): readings rounded to whole steps err by step/√12 RMS."""
    rng = np.random.default_rng(12)
    step = 3e-6
    truth = rng.uniform(0.0, 1.0, size=400_000)
    error = np.round(truth / step) * step - truth
    assert quantization_std(step) == pytest.approx(np.std(error), rel=5e-3)
    for name in ("rowc", "caroca"):
        model = load_robot(CONFIG / f"{name}.toml")
        assert length_noise(model) == pytest.approx(Weights.of(model).length / math.sqrt(12.0))


def test_the_model_test_is_the_chi_square_quantile_and_passes_no_closures():
    from scipy.stats import chi2

    assert model_test(np.zeros(0), 1e-6) == (True, 0.0)
    n, sigma = 20, 2e-6
    edge = math.sqrt(chi2.ppf(0.999, n) / n) * sigma  # every closure there: Σ(r/σ)² at the quantile
    ok, ratio = model_test(np.full(n, edge * 0.999), sigma)
    assert ok and ratio == pytest.approx(0.999 * edge / sigma)
    assert not model_test(np.full(n, edge * 1.001), sigma)[0]
    # at 0.99999 the quantile is 1.14·edge
    assert model_test(np.full(n, edge * 1.1), sigma, confidence=0.99999)[0]
