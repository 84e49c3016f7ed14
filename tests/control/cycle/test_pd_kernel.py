"""The compiled PID + feed-forward kernel against a numpy transcription of the law
(``M (a_d + kp e + ki ∫e + kd ė) − w_g − w_e``, docs/control.md) on seeded random states,
and its rotation helpers against cdprctl.core.rotation (near-π branch included)."""

from __future__ import annotations

import numpy as np
import pytest

from cdprctl.control.cycle.pd_kernel import Pid, Platform, PoseEstimate, Reference, pd_wrench_kernel
from cdprctl.core.rotation import exp_so3, exp_so3_kernel, log_so3, log_so3_kernel


def reference(ref_x, ref_v, ref_a, p, R, v, w, R_home, kp, kd, ki, integral, lim, integ, dt,
              mass, inertia, com, g, ext):  # fmt: skip
    integral = integral.copy()
    err = np.zeros(6)
    err[:3] = ref_x[:3] - p
    err[3:] = log_so3(exp_so3(ref_x[3:]) @ R_home @ R.T)
    if integ:
        integral = np.clip(integral + err * dt, -lim, lim)
    acc = ref_a + kp * err + ki * integral + kd * (ref_v - np.concatenate([v, w]))
    Iw = R @ inertia @ R.T
    f = mass * g
    gw = np.concatenate([f, np.cross(R @ com, f)])
    wrench = np.concatenate([mass * acc[:3], Iw @ acc[3:] + np.cross(w, Iw @ w)]) - gw - ext
    return err, integral, wrench


@pytest.mark.parametrize("seed", range(20))
def test_kernel_matches_the_numpy_law(seed):
    rng = np.random.default_rng(seed)
    ref_x, ref_v, ref_a = rng.normal(size=6), rng.normal(size=6), rng.normal(size=6)
    ref_x[3:] *= 0.3
    p, v, w = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    R = exp_so3(rng.normal(size=3) * 0.5)
    R_home = exp_so3(rng.normal(size=3) * 0.5)
    A = rng.normal(size=(3, 3))
    inertia = A @ A.T + np.eye(3)
    com, g, ext = rng.normal(size=3) * 0.1, np.array([0.0, 0.0, -9.81]), rng.normal(size=6)
    integral = rng.normal(size=6) * 0.01
    gains = rng.uniform(0.5, 3.0, size=(3, 6))  # per-axis kp, kd, ki
    lim = rng.uniform(0.005, 0.05, size=6)
    args = (gains[0], gains[1], gains[2], lim, True, 0.002, 12.0, inertia, com, g, ext)
    kp, kd, ki, lim, integ, dt, mass = args[:7]
    err_ref, int_ref, wrench_ref = reference(ref_x, ref_v, ref_a, p, R, v, w, R_home, kp, kd, ki,
                                             integral, lim, integ, dt, mass, inertia, com, g,
                                             ext)  # fmt: skip
    err, wrench, feedback = np.zeros(6), np.zeros(6), np.zeros(6)
    integral_k = integral.copy()
    pd_wrench_kernel(
        Reference(ref_x, ref_v, ref_a),
        PoseEstimate(p, R, v, w),
        Pid(kp, kd, ki, integral_k, lim),
        integ,
        dt,
        Platform(R_home, mass, inertia, com, g),
        ext,
        np.zeros((3, 3)),
        np.zeros((3, 3)),
        np.zeros(15),
        err,
        wrench,
        feedback,
    )
    np.testing.assert_allclose(err, err_ref, atol=1e-12)
    np.testing.assert_allclose(integral_k, int_ref, atol=1e-12)
    np.testing.assert_allclose(wrench, wrench_ref, rtol=1e-10, atol=1e-10)
    # the feedback part: the law's wrench less the law with the PID's gains at zero
    zero = np.zeros(6)
    _, _, ff_ref = reference(ref_x, ref_v, ref_a, p, R, v, w, R_home, zero, zero, zero,
                             integral, lim, False, dt, mass, inertia, com, g, ext)  # fmt: skip
    np.testing.assert_allclose(feedback, wrench_ref - ff_ref, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 0.3, 2.0, np.pi - 1e-7, np.pi])
def test_rotation_helpers_match(angle):
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    phi = angle * axis
    R = np.zeros((3, 3))
    exp_so3_kernel(phi[0], phi[1], phi[2], R)
    np.testing.assert_allclose(R, exp_so3(phi), atol=1e-14)
    out = np.zeros(3)
    log_so3_kernel(R, out)
    back = np.zeros((3, 3))
    exp_so3_kernel(out[0], out[1], out[2], back)
    np.testing.assert_allclose(back, R, atol=1e-6)  # same rotation (±axis at π)
    np.testing.assert_allclose(np.linalg.norm(out), angle, atol=1e-6)
