"""Geometric calibration from the drives alone: the anchors, each drum's radius, the encoders'
offsets and every sample's pose, identified from motor angles and tensions at rest at K poses
spread over the workspace (``cdprctl calibrate geometry``, docs/homing.md).

Unknowns: every anchor ``a_i`` (m, base frame) but the reference ones (taken as drawn: they fix
the robot's frame, the gauge), each drum's scale ``s_i`` (its radius / the file's) and each
sample's pose ``x_k`` (position m; rotation vector rad from the home orientation). The
encoders' offsets follow from sample 0 (as in :mod:`identify`). Residuals, for point anchors
(exit points; pulleys are not identified here):

* length closure, k ≥ 1: ``L_i(x_k; a_i) − [l0_ki + t_ki c(l0_ki)]`` with ``L_i = |a_i − p_k −
  R_k b_i|`` (the inverse kinematics of a CDPR, e.g. Pott 2018, eq. (2.2)), the unstretched
  ``l0_ki = l0_0i − (r_i/G_i) s_i (θ_ki − θ_0i)``, ``l0_0`` the cable law solved at ``L(x_0)``;
  weight ``1/σ_L``;
* static equilibrium, every k: ``W(x_k; a) t_k + w_g(R_k)`` with the true tensions
  ``t_ki = τ_ki G_i / (r_i s_i)``: a drum wound larger pulls less per N·m (forces weight
  ``1/σ_F``, moments ``1/(σ_F reach)``).

Solved with ``scipy.optimize.least_squares`` (trust-region reflective, the Jacobian's sparsity
given: a pose touches its own sample's rows and, through ``l0_0``, the length rows of the
others). The residuals' variance factor against the weights is the model test
(``identify.model_test``, in ``geometry_procedure``): a model error the unknowns cannot absorb
leaves residuals larger than the drives' resolution explains, and the record is refused rather
than trusted.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from cdprctl.core.numerics import cable_compliance_py, compliance_of, unstretched_lengths
from cdprctl.core.rotation import exp_so3, matrix_to_rpy, skew
from cdprctl.model.robot import RobotModel


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    """SO(3)'s left Jacobian: ``exp(φ + dφ) ≈ exp([J_l(φ) dφ]×) exp(φ)`` (Barfoot, *State
    Estimation for Robotics*, 2017, eq. (7.77)): the rotation vector's step as an angular
    displacement in the base frame."""
    angle = float(np.linalg.norm(phi))
    K = skew(phi)
    if angle < 1e-8:
        return np.eye(3) + 0.5 * K
    return (np.eye(3) + (1.0 - math.cos(angle)) / angle**2 * K
            + (angle - math.sin(angle)) / angle**3 * K @ K)  # fmt: skip


@dataclasses.dataclass
class GeometrySamples:
    """K samples at rest: motor angles (K × m, rad), the tensions as the file's drums read the
    motor torques (K × m, N: torque · G / r_file), and each sample's planned pose (K × 6: m;
    rotation vector rad from the home orientation), the solver's start."""

    theta: np.ndarray
    tension: np.ndarray
    guess: np.ndarray


@dataclasses.dataclass
class GeometryResult:
    anchors: np.ndarray  # m × 3, base frame
    drum_scale: np.ndarray  # identified radius / the file's, per cable
    theta_zero: np.ndarray  # rad: each motor's angle where l0 is its home length (as identified)
    poses: np.ndarray  # K × 6
    pose: list[float]  # x, y, z (m), roll, pitch, yaw (rad) of sample 0
    residual_rms: float  # m, of the length closures
    force_rms: float  # N, of the equilibrium residuals
    variance_factor: float  # Σr²/dof of the weighted residuals: about 1 when the model holds
    dof: int
    condition: float  # of the column-normalised weighted Jacobian
    std_anchors: np.ndarray  # m × 3, m: predicted σ (0 for the reference anchors)
    std_drum_scale: np.ndarray  # per cable
    std_pose: list[float]  # m, rad: sample 0's predicted σ
    success: bool
    message: str


class GeometryIdentification:
    """The least-squares problem of one robot with point anchors; ``solve(samples)``.

    ``reference``: the anchors taken as drawn (indices, at least three not on one line: they
    fix the frame). ``sigma_length`` (m) and ``sigma_tension`` (N): the residuals' scale, from
    the drives' resolution (``identify.Weights.of``)."""

    def __init__(self, model: RobotModel, reference: list[int], sigma_length: float,
                 sigma_tension: float):  # fmt: skip
        if any(c.pulley is not None for c in model.cables):
            raise ValueError("geometric calibration identifies exit points: cables with "
                             "[cables.pulley] are not supported")  # fmt: skip
        self.model, self.m = model, model.n_cables
        self.reference = sorted(set(reference))
        self.free = [i for i in range(self.m) if i not in self.reference]
        self.anchors0 = np.array([c.anchor for c in model.cables], float)
        self.b = np.asarray(model.attachments, float)  # m × 3, platform frame
        self.ratio = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
        self.law = compliance_of(model.cables)
        self.R_home = np.asarray(model.home.rotation, float)
        self.sigma_l, self.sigma_t = sigma_length, sigma_tension
        reach = float(np.max(np.linalg.norm(self.b, axis=1))) or 1.0
        sigma_f = sigma_tension * math.sqrt(self.m)
        self.force_weight = np.r_[np.full(3, 1.0 / sigma_f), np.full(3, 1.0 / (sigma_f * reach))]
        self.n_geo = 3 * len(self.free) + self.m

    # -- the model -------------------------------------------------------------------------
    def _unpack(self, z: np.ndarray, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        anchors = self.anchors0.copy()
        anchors[self.free] = z[: 3 * len(self.free)].reshape(-1, 3)
        scales = z[3 * len(self.free) : self.n_geo]
        poses = z[self.n_geo :].reshape(K, 6)
        return anchors, scales, poses

    def _lengths_and_wrench(self, anchors: np.ndarray, x: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
        """L (m), W (6 × m: unit vectors towards the anchors, their moments about the
        platform's reference point) and R at pose ``x``."""
        R = exp_so3(x[3:6]) @ self.R_home
        rb = self.b @ R.T  # m × 3: attachments in the base frame, from the platform's point
        d = anchors - x[:3] - rb
        L = np.linalg.norm(d, axis=1)
        u = d / L[:, None]
        return L, np.vstack([u.T, np.cross(rb, u).T]), R

    def residuals(self, z: np.ndarray, s: GeometrySamples) -> np.ndarray:
        K = s.theta.shape[0]
        anchors, scales, poses = self._unpack(z, K)
        tension = s.tension / scales  # the file's drum read the torques; the real one differs
        out = []
        l0_start = np.zeros(self.m)
        for k in range(K):
            L, W, R = self._lengths_and_wrench(anchors, poses[k])
            if k == 0:
                l0_start = unstretched_lengths(self.law, L, tension[0])
            else:
                l0 = l0_start - self.ratio * scales * (s.theta[k] - s.theta[0])
                c = cable_compliance_py(*self.law, l0)  # type: ignore[arg-type]
                out.append((L - (l0 + tension[k] * c)) / self.sigma_l)
            out.append((W @ tension[k] + self.model.gravity_wrench(R)) * self.force_weight)
        return np.concatenate(out)

    def jacobian(self, z: np.ndarray, s: GeometrySamples) -> np.ndarray:
        """∂residuals/∂z, analytic (``tests/calibration/test_geometry_calibration.py`` checks it
        against finite differences): the derivatives of ``L``, ``u`` and the moment arms by the
        anchors, the position and the rotation (through ``left_jacobian``), and of the tensions
        and the unstretched lengths by the drum scales."""
        K = s.theta.shape[0]
        m, g, nf = self.m, self.n_geo, len(self.free)
        anchors, scales, poses = self._unpack(z, K)
        col_a = {i: 3 * j for j, i in enumerate(self.free)}  # cable → its anchor's columns
        tension = s.tension / scales
        dt_ds = -tension / scales  # K × m
        c0 = self.law.inv_k_fixed + self.law.inv_es * self.law.l_winch + self.law.inv_spring
        e = self.law.inv_es
        J = np.zeros(((K - 1) * m + 6 * K, g + 6 * K))
        f = self.model.platform.mass * np.asarray(self.model.gravity, float)
        com = np.asarray(self.model.platform.com, float)
        dL0 = np.zeros((m, 6))  # sample 0's dL/d(p, δ)
        dL0_da = np.zeros((m, 3))
        L0 = np.zeros(m)
        r = 0
        for k in range(K):
            x = poses[k]
            R = exp_so3(x[3:6]) @ self.R_home
            Jl = left_jacobian(x[3:6])
            rb = self.b @ R.T
            d = anchors - x[:3] - rb
            L = np.linalg.norm(d, axis=1)
            u = d / L[:, None]
            mom = np.cross(rb, u)
            dL = np.hstack([-u, -mom @ Jl])  # m × 6: by p and by δ
            pc = g + 6 * k  # pose k's first column
            if k == 0:
                dL0, dL0_da, L0 = dL, u.copy(), L
                l0s = (L0 - tension[0] * c0) / (1.0 + tension[0] * e)
                dl0s_ds = -dt_ds[0] * (c0 + L0 * e) / (1.0 + tension[0] * e) ** 2
            else:
                tk = tension[k]
                l0k = l0s - self.ratio * scales * (s.theta[k] - s.theta[0])
                gain = (1.0 + tk * e) / (1.0 + tension[0] * e)  # l0_k's share of L_0
                rows = slice(r, r + m)
                J[rows, pc : pc + 6] = dL / self.sigma_l
                J[rows, g : g + 6] -= gain[:, None] * dL0 / self.sigma_l
                for i in range(m):
                    if i in col_a:
                        c = col_a[i]
                        J[r + i, c : c + 3] = (u[i] - gain[i] * dL0_da[i]) / self.sigma_l
                dl0k_ds = dl0s_ds - self.ratio * (s.theta[k] - s.theta[0])
                dfs = -dl0k_ds * (1.0 + tk * e) - (l0k * e + c0) * dt_ds[k]
                J[r + np.arange(m), 3 * nf + np.arange(m)] = dfs / self.sigma_l
                r += m
            # equilibrium: Σ u_i t_i, Σ m_i t_i + (R com) × f
            t = tension[k]
            w = self.force_weight
            Pm = [(np.eye(3) - np.outer(u[i], u[i])) / L[i] for i in range(m)]
            dF_dp, dF_dw = np.zeros((3, 3)), np.zeros((3, 3))
            dM_dp, dM_dw = np.zeros((3, 3)), skew(f) @ skew(R @ com)
            for i in range(m):
                P, S = Pm[i], skew(rb[i])
                dF_dp -= t[i] * P
                dF_dw += t[i] * P @ S
                dM_dp -= t[i] * S @ P
                dM_dw += t[i] * (skew(u[i]) @ S + S @ P @ S)
                if i in col_a:
                    c = col_a[i]
                    J[r : r + 3, c : c + 3] = t[i] * P * w[:3, None]
                    J[r + 3 : r + 6, c : c + 3] = t[i] * S @ P * w[3:, None]
                Wi = np.r_[u[i], mom[i]]
                J[r : r + 6, 3 * nf + i] = Wi * dt_ds[k, i] * w
            J[r : r + 3, pc : pc + 3] = dF_dp * w[:3, None]
            J[r : r + 3, pc + 3 : pc + 6] = dF_dw @ Jl * w[:3, None]
            J[r + 3 : r + 6, pc : pc + 3] = dM_dp * w[3:, None]
            J[r + 3 : r + 6, pc + 3 : pc + 6] = dM_dw @ Jl * w[3:, None]
            r += 6
        return J

    def sparsity(self, K: int) -> lil_matrix:
        """Every row depends on the geometry; sample k's on x_k, and its lengths on x_0."""
        m, g = self.m, self.n_geo
        rows = (K - 1) * m + 6 * K
        A = lil_matrix((rows, g + 6 * K), dtype=int)
        A[:, :g] = 1
        r = 0
        for k in range(K):
            if k:
                A[r : r + m, g : g + 6] = 1
                A[r : r + m, g + 6 * k : g + 6 * k + 6] = 1
                r += m
            A[r : r + 6, g + 6 * k : g + 6 * k + 6] = 1
            r += 6
        return A

    #: m and fraction: how far an anchor and a drum may be from the file (further, it is
    #: another robot, or the data are wrong: rowc's solver once went 5 m off without them)
    ANCHOR_BOUND = 0.1
    SCALE_BOUND = 0.05

    def bounds(self, K: int) -> tuple[np.ndarray, np.ndarray]:
        a = self.anchors0[self.free].ravel()
        lo = np.r_[a - self.ANCHOR_BOUND, np.full(self.m, 1.0 - self.SCALE_BOUND),
                   np.full(6 * K, -np.inf)]  # fmt: skip
        hi = np.r_[a + self.ANCHOR_BOUND, np.full(self.m, 1.0 + self.SCALE_BOUND),
                   np.full(6 * K, np.inf)]  # fmt: skip
        return lo, hi

    def at_bound(self, r: GeometryResult) -> bool:
        """Whether an anchor or a drum ended at its bound (not identified: refuse)."""
        a = r.anchors[self.free] - self.anchors0[self.free]
        return bool(np.any(np.abs(a) > 0.99 * self.ANCHOR_BOUND)
                    or np.any(np.abs(r.drum_scale - 1.0) > 0.99 * self.SCALE_BOUND))  # fmt: skip

    # -- the solution ----------------------------------------------------------------------
    def solve(self, s: GeometrySamples) -> GeometryResult:
        K = s.theta.shape[0]
        z0 = np.concatenate([self.anchors0[self.free].ravel(), np.ones(self.m), s.guess.ravel()])
        lo, hi = self.bounds(K)
        res = least_squares(
            self.residuals, z0, jac=self.jacobian, args=(s,), bounds=(lo, hi), method="trf",
            x_scale="jac", xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=100,
        )  # fmt: skip
        anchors, scales, poses = self._unpack(res.x, K)
        J = res.jac.toarray() if hasattr(res.jac, "toarray") else np.asarray(res.jac)
        norms = np.linalg.norm(J, axis=0)
        sv = np.linalg.svd(J / np.where(norms > 0, norms, 1.0), compute_uv=False)
        condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
        r = res.fun
        dof = max(1, r.size - res.x.size)
        variance_factor = float(r @ r) / dof
        try:  # σ from the weights alone: a model error shows in the χ² test, not in a wider σ
            cov = np.linalg.inv(J.T @ J) * max(1.0, variance_factor)
            std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        except np.linalg.LinAlgError:
            std = np.full(res.x.size, math.inf)
        std_anchors = np.zeros((self.m, 3))
        std_anchors[self.free] = std[: 3 * len(self.free)].reshape(-1, 3)
        lengths, forces = [], []
        i = 0
        for k in range(K):
            if k:
                lengths.append(r[i : i + self.m] * self.sigma_l)
                i += self.m
            forces.append(r[i : i + 6] / self.force_weight)
            i += 6
        L0, _, R0 = self._lengths_and_wrench(anchors, poses[0])
        tension0 = s.tension[0] / scales
        l0_start = unstretched_lengths(self.law, L0, tension0)
        home = np.r_[self.model.home.position, 0.0, 0.0, 0.0]
        l_home = self._lengths_and_wrench(anchors, home)[0]
        theta_zero = s.theta[0] - (l_home - l0_start) / (self.ratio * scales)
        return GeometryResult(
            anchors=anchors,
            drum_scale=scales.copy(),
            theta_zero=theta_zero,
            poses=poses.copy(),
            pose=[*map(float, poses[0][:3]), *matrix_to_rpy(R0)],
            residual_rms=float(np.sqrt(np.mean(np.concatenate(lengths) ** 2))) if K > 1 else 0.0,
            force_rms=float(np.sqrt(np.mean(np.concatenate(forces) ** 2))),
            variance_factor=variance_factor,
            dof=dof,
            condition=condition,
            std_anchors=std_anchors,
            std_drum_scale=std[3 * len(self.free) : self.n_geo].copy(),
            std_pose=[float(x) for x in std[self.n_geo : self.n_geo + 6]],
            success=bool(res.success),
            message=str(res.message),
        )
