"""Self-calibration of the initial pose from redundant cable lengths (after the initial-pose
self-calibration of Zoffoli et al. on over-sensed CDPRs), with the cables' stretch modelled.

Samples k = 0 … K−1 are taken at rest: motor angles ``θ_k`` (rad) and tensions ``t_k`` (N, from
the drives' torques). Unknowns: the pose of sample 0 (the start) ``x_0`` and of every other
sample ``x_k`` (position m, rotation vector rad from the home orientation), optionally each
drum's pay-out scale ``s``. Residuals:

* length closure, k ≥ 1: ``L(x_k) − [l0_k + t_k c(l0_k)]`` with the unstretched lengths
  ``l0_k = l0_0 − (r/G) s (θ_k − θ_0)`` and ``l0_0`` the cable law solved at ``L(x_0)``,
  ``t_0`` (``numerics.unstretched_lengths``); weight ``1/σ_L``;
* static equilibrium, every k: ``W(x_k) t_k + w_g(R_k)`` (forces weight ``1/σ_F``, moments
  ``1/σ_M``): the tensions' directions tell the pose too, and where the lengths alone leave a
  direction nearly unobservable (CAROCA's height: its anchors share one plane) they decide it.

The increments see the pose only through the change of the cable directions with it, so the
observability grows with the spread of the samples and falls with the cables' length: the
condition number of the column-normalised weighted Jacobian and the pose's predicted standard
deviation (the least-squares covariance scaled by the a-posteriori variance factor) say how well
the data decide it (docs/homing.md).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from cdprctl.core.numerics import cable_compliance_py, compliance_of, unstretched_lengths
from cdprctl.core.rotation import exp_so3, matrix_to_rpy
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel


@dataclasses.dataclass
class Samples:
    """K samples at rest: motor angles (K × m, rad) and tensions (K × m, N); ``guess``
    (K × 6): each sample's nominal pose (m; rotation vector rad from the home orientation)."""

    theta: np.ndarray
    tension: np.ndarray
    guess: np.ndarray


@dataclasses.dataclass
class Identified:
    pose: list[float]  # x, y, z (m), roll, pitch, yaw (rad) of sample 0
    poses: np.ndarray  # K × 6, position and rotation vector from the home orientation
    drum_scale: np.ndarray  # per cable
    theta_zero: np.ndarray  # rad: each motor's angle where l0 = its length at home
    residual_rms: float  # m, of the length residuals
    sample_residuals: list[float]  # m, RMS of each sample's length residuals (0 for k = 0)
    force_rms: float  # N, of the equilibrium residuals
    condition: float
    std: list[float]  # m, rad: predicted standard deviation of x_0 (position, rotation)
    success: bool
    message: str
    variance_factor: float  # the weighted residuals' Σr²/dof
    dof: int  # residuals − unknowns, at least 1
    length_residuals: np.ndarray  # m, (K − 1)·m: every sample's length closures after the fit


@dataclasses.dataclass(frozen=True)
class Weights:
    length: float  # m: σ of a length closure (stretch model, encoder, rest)
    tension: float  # N: σ of a measured tension (torque resolution, friction at rest)

    @classmethod
    def of(cls, model: RobotModel) -> Weights:
        """From the drives' resolution: a tension is read to one count of the torque (0x6077,
        per mille of the rated torque) through the drum, at least 1 N; a length closure to
        the stretch of that tension error plus one encoder count (rowc ~8 µm and 1 N, CAROCA
        ~7 µm and 2 N)."""
        w = [c.winch for c in model.cables]
        ratio = np.array([x.drum_radius / x.gear_ratio for x in w])
        tension = max(1.0, float(np.max(model.drives.rated_torque / 1000.0 / ratio)))
        kin = KinematicsData(model)
        inverse_kinematics(model, kin, model.home.position, model.home.rotation)
        compliance = float(np.max(1.0 / model.cable_stiffness(kin.length)))
        count = float(np.max(2.0 * math.pi * ratio / [x.encoder_counts_per_rev for x in w]))
        return cls(length=compliance * tension + count, tension=tension)


def quantization_std(step: float) -> float:
    """The σ of a reading rounded to whole steps of ``step`` (the error uniform over one
    step): step/√12."""
    return step / math.sqrt(12.0)


def length_noise(model: RobotModel) -> float:
    """m: the σ of a length closure that the drives' resolution explains, quantization's:
    the encoder's count through the drum, and the stretch of one torque count's tension
    (``Weights.of`` takes whole counts: weights, not the noise). Measured in lock-step (20
    starts without plant errors, docs/homing.md): the closures' RMS stays within it (rowc
    3.7-7.9 µm against 7.8 µm, CAROCA 1.2-1.8 against 1.9 µm)."""
    return quantization_std(Weights.of(model).length)


def model_test(length_residuals: np.ndarray, sigma: float,
               confidence: float = 0.999) -> tuple[bool, float]:  # fmt: skip
    """Whether the length closures are what the drives' resolution explains: Σ(r/σ)² within
    the χ²(n) quantile at ``confidence`` (the fitted residuals are smaller than the noise,
    so a correct model passes more often than ``confidence`` says). Returns (ok, the RMS over
    σ). A geometry the file does not describe leaves closures the poses cannot absorb."""
    from scipy.stats import chi2

    n = int(length_residuals.size)
    if n == 0:
        return True, 0.0
    q = float(np.sum((length_residuals / sigma) ** 2))
    return q <= float(chi2.ppf(confidence, n)), math.sqrt(q / n)


_TINY = np.finfo(float).tiny


class Identification:
    """The least-squares problem of one robot; ``solve(samples)``."""

    def __init__(self, model: RobotModel, fit_drum_scales: bool, weights: Weights | None = None):
        self.model = model
        self.m = model.n_cables
        self.fit_scales = fit_drum_scales
        self.w = weights or Weights.of(model)
        self.law = compliance_of(model.cables)
        self.ratio = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
        self.R_home = model.home.rotation
        self.kin = KinematicsData(model)
        inverse_kinematics(model, self.kin, model.home.position, self.R_home)
        self.l_home = self.kin.length.copy()
        reach = float(np.max(np.linalg.norm(model.attachments, axis=1))) or 1.0
        sigma_f = self.w.tension * math.sqrt(self.m)
        self.force_weight = np.r_[np.full(3, 1.0 / sigma_f), np.full(3, 1.0 / (sigma_f * reach))]

    def _pose(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x[:3], exp_so3(x[3:]) @ self.R_home

    def _at(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        p, R = self._pose(x)
        inverse_kinematics(self.model, self.kin, p, R)
        return self.kin.length.copy(), np.array(self.kin.W), R

    def _unpack(self, z: np.ndarray, K: int) -> tuple[np.ndarray, np.ndarray]:
        poses = z[: 6 * K].reshape(K, 6)
        scales = z[6 * K :] if self.fit_scales else np.ones(self.m)
        return poses, scales

    def _equilibrium(self, W: np.ndarray, tension: np.ndarray, R: np.ndarray) -> np.ndarray:
        """Weighted: the wrench the tensions and gravity leave on the platform at rest."""
        return (W @ tension + self.model.gravity_wrench(R)) * self.force_weight

    def residuals(self, z: np.ndarray, s: Samples) -> np.ndarray:
        """Weighted: sample 0's equilibrium (6), then per sample k ≥ 1 its length closures
        (m) and its equilibrium (6)."""
        K = s.theta.shape[0]
        poses, scales = self._unpack(z, K)
        L0, W0, R0 = self._at(poses[0])
        l0_start = unstretched_lengths(self.law, L0, s.tension[0])
        out = [self._equilibrium(W0, s.tension[0], R0)]
        for k in range(1, K):
            L, W, R = self._at(poses[k])
            l0 = l0_start - self.ratio * scales * (s.theta[k] - s.theta[0])
            # the cable law, on every cable at once (the rule is plain arithmetic)
            c = cable_compliance_py(*self.law, l0)  # type: ignore[arg-type]
            out.append((L - (l0 + s.tension[k] * c)) / self.w.length)
            out.append(self._equilibrium(W, s.tension[k], R))
        return np.concatenate(out)

    def _sparsity(self, K: int) -> lil_matrix:
        """Which unknowns each residual depends on (rows as in ``residuals``): a sample's
        equilibrium on its own pose; its length closure of cable i on x_0, its own pose and
        drum i's scale."""
        m = self.m
        n = 6 * K + (m if self.fit_scales else 0)
        A = lil_matrix((6 + (K - 1) * (m + 6), n), dtype=int)
        A[0:6, 0:6] = 1
        cables = np.arange(m)
        for k in range(1, K):
            r = 6 + (k - 1) * (m + 6)
            A[r : r + m, 0:6] = 1
            A[r : r + m + 6, 6 * k : 6 * k + 6] = 1
            if self.fit_scales:
                A[r + cables, 6 * K + cables] = 1
        return A

    def solve(self, s: Samples) -> Identified:
        K, m = s.theta.shape
        z0 = np.concatenate([s.guess.ravel(), np.ones(m) if self.fit_scales else []])
        res = least_squares(
            self.residuals, z0, args=(s,), jac_sparsity=self._sparsity(K), method="trf",
            x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=200,
        )  # fmt: skip
        poses, scales = self._unpack(res.x, K)
        J = res.jac.toarray() if hasattr(res.jac, "toarray") else np.asarray(res.jac)
        # a column that no residual sees (a drum that never turned) stays zero, and unknowns
        # beyond the residuals' count are undetermined: singular values of zero, both
        sv = np.linalg.svd(J / np.maximum(np.linalg.norm(J, axis=0), _TINY), compute_uv=False)
        sv = np.r_[sv, np.zeros(J.shape[1] - sv.size)]
        with np.errstate(divide="ignore"):
            condition = float(sv[0] / sv[-1])
        r = res.fun
        per_sample = r[6:].reshape(K - 1, m + 6)
        lengths = per_sample[:, :m] * self.w.length  # m: sample k ≥ 1's closures, row k − 1
        length_res = lengths.ravel()
        forces = np.concatenate([r[:6], per_sample[:, m:].ravel()]) / np.tile(self.force_weight, K)
        dof = max(1, r.size - res.x.size)
        # the a-posteriori variance factor: the residuals' own scale against the weights'
        # (not below a tenth: a few lucky samples do not make the pose exact)
        variance_factor = float(r @ r) / dof
        chi2 = max(0.1, variance_factor)
        try:
            cov = np.linalg.inv(J.T @ J) * chi2
            std = np.sqrt(np.maximum(np.diag(cov)[:6], 0.0))
        except np.linalg.LinAlgError:
            std = np.full(6, math.inf)
        p0, R0 = self._pose(poses[0])
        L0 = self._at(poses[0])[0]
        l0_start = unstretched_lengths(self.law, L0, s.tension[0])
        theta_zero = s.theta[0] - (self.l_home - l0_start) / (self.ratio * scales)
        return Identified(
            pose=[*map(float, p0), *matrix_to_rpy(R0)],
            poses=poses.copy(),
            drum_scale=scales.copy(),
            theta_zero=theta_zero,
            residual_rms=float(np.sqrt(np.mean(length_res**2))) if length_res.size else 0.0,
            sample_residuals=[0.0, *(np.sqrt(np.mean(lengths**2, axis=1))).tolist()],
            force_rms=float(np.sqrt(np.mean(forces**2))),
            condition=condition,
            std=[float(x) for x in std],
            success=bool(res.success),
            message=str(res.message),
            variance_factor=variance_factor,
            dof=dof,
            length_residuals=length_res,
        )

