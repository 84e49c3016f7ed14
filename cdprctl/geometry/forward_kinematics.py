"""Forward kinematics: the platform pose from measured cable lengths.

Levenberg-Marquardt on the inverse kinematics (:mod:`cdprctl.geometry.kinematics`), warm-started
from the previous pose, compiled with numba (a few µs per solve). The length Jacobian is
``∂l/∂X = −Wᵀ`` for a displacement screw ``δX = [δp, δφ]`` (rotation vector applied on the
left), so each step solves
``(W Wᵀ + μ I) δX = W (l(X) − l_meas)``. The call never raises: failures are a status.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from cdprctl.core.numerics import (
    cable_compliance_py,
    compliance_terms,
    cycle_kernel,
    forward_substitution,
    kernel_args,
    matmul_into,
)
from cdprctl.core.rotation import FloatArray, exp_so3_kernel
from cdprctl.geometry.kinematics import KinematicsData, ik_kernel

if TYPE_CHECKING:
    from cdprctl.model.robot import RobotModel


class FKStatus(enum.IntEnum):
    CONVERGED = 0
    MAX_ITERATIONS = 1  # best pose returned, residual above tolerance
    DEGENERATE = 2  # a cable of zero length or a non-finite value on the way
    BAD_INPUT = 3  # non-finite measured lengths or start pose
    INCONSISTENT = 4  # converged, but the lengths cannot all be met: least-squares pose


class FKLimits(NamedTuple):
    """When the iteration stops: ``tolerance`` (m RMS of the length residual),
    ``step_tolerance`` (largest step component, m or rad), ``max_iterations``, and
    ``max_residual`` (m RMS) above which a converged pose is INCONSISTENT."""

    tolerance: float
    step_tolerance: float
    max_iterations: int
    max_residual: float


class FKWork(NamedTuple):
    """The iteration's working arrays, taken once (the solve takes no block per call): the
    normal equations ``lhs`` (6×6) and ``rhs`` (6), their Cholesky factor ``L`` (6×6), the
    forward solve's ``y`` and the ``step`` δX (m, rad), the trial pose ``p_new`` (m),
    ``R_new``, the step's rotation ``E`` and two 3×3 products ``A``, ``B``."""

    lhs: np.ndarray
    rhs: np.ndarray
    L: np.ndarray
    y: np.ndarray
    step: np.ndarray
    p_new: np.ndarray
    R_new: np.ndarray
    E: np.ndarray
    A: np.ndarray
    B: np.ndarray


def fk_work() -> tuple:
    """A new ``FKWork`` as the kernels take it (``kernel_args``)."""
    six, three = np.zeros((6, 6)), np.zeros((3, 3))
    return kernel_args(
        FKWork(six, np.zeros(6), six.copy(), np.zeros(6), np.zeros(6), np.zeros(3),
               three, three.copy(), three.copy(), three.copy())
    )  # fmt: skip


@dataclass
class FKResult:
    position: FloatArray  # m, base frame
    rotation: FloatArray  # platform → base
    residual: float  # m, RMS of l(X) − l_meas at the returned pose
    iterations: int
    status: FKStatus


class ForwardKinematics:
    """Solver with its own workspace, for one robot.

    Parameters
    ----------
    model : RobotModel
    tolerance : float
        Converged when the RMS length residual (m) is below it ...
    step_tolerance : float
        ... or when a Gauss-Newton step is smaller than this (m and rad): the residual after
        it is of the order of the step squared, so the stepped pose is returned without one
        more inverse kinematics (the reported residual is then the linearised one).
    max_iterations : int
    max_residual : float
        RMS residual (m) above which a converged least-squares pose is reported
        ``INCONSISTENT``: the lengths (encoders, stretch model) disagree with any pose.
    """

    def __init__(
        self,
        model: RobotModel,
        tolerance: float = 1e-9,
        step_tolerance: float = 1e-5,
        max_iterations: int = 30,
        max_residual: float = 1e-4,
    ):
        self.model = model
        self.data = KinematicsData(model)
        limits = FKLimits(tolerance, step_tolerance, int(max_iterations), max_residual)
        self.limits = kernel_args(limits)
        m = model.n_cables
        self._p = np.zeros(3)
        self._R = np.eye(3)
        self._info = np.zeros(3)  # residual, iterations, status
        self._res = np.zeros(m)
        self.work = fk_work()

    def solve(
        self,
        lengths: FloatArray,
        position0: FloatArray,
        rotation0: FloatArray,
    ) -> FKResult:
        """Pose whose cable lengths (m, pulley arcs included) match ``lengths``.

        ``position0``/``rotation0`` is the warm start (the last pose, in the loop).
        """
        d = self.data
        p, R, info = self._p, self._R, self._info
        p[:] = position0
        R[:] = rotation0
        fk_kernel(d.arrays, lengths, p, R, self.limits, self._res, info, self.work)
        d.position[:] = p
        d.rotation[:] = R
        status = FKStatus(int(info[2]))
        return FKResult(p.copy(), R.copy(), float(info[0]), int(info[1]), status)


@cycle_kernel
def _exp_left(phi0, phi1, phi2, R, E, out):  # pragma: no cover - compiled
    """``out`` ← ``exp([φ]×) @ R`` (``E`` the exponential's scratch)."""
    exp_so3_kernel(phi0, phi1, phi2, E)
    matmul_into(E, R, out)


@cycle_kernel
def copy_pose(p_from, R_from, p, R):  # pragma: no cover - compiled
    """``p``, ``R`` ← ``p_from``, ``R_from`` element by element (a slice assignment may copy
    through a temporary when the arrays could overlap: a block, and not without reference
    counting)."""
    for i in range(3):
        p[i] = p_from[i]
        for j in range(3):
            R[i, j] = R_from[i, j]


@cycle_kernel
def rotation_since(R, R_before, out):  # pragma: no cover - compiled
    """``out`` ← ``R R_beforeᵀ``, the rotation from ``R_before`` to ``R`` (base frame)."""
    matmul_into(R, R_before.T, out)


@cycle_kernel
def _cholesky_solve6(A, b, L, y, x):  # pragma: no cover - compiled
    """``x`` ← the solution of the SPD 6×6 system ``A x = b`` by Cholesky (``L``, ``y`` its
    scratch); False when ``A`` is not positive definite."""
    n = 6
    L[:, :] = 0.0
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            x[:] = 0.0
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    y[:] = 0.0
    forward_substitution(L, b, y)
    x[:] = 0.0
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return True


@cycle_kernel
def _polar_step(R, A, B):  # pragma: no cover - compiled
    """``R`` ← ``0.5 R (3 I − RᵀR)``, one Newton step of the polar decomposition (``A``, ``B``
    scratch; the products BLAS's, as ``@`` took them: the same bits)."""
    matmul_into(R.T, R, A)
    for i in range(3):
        for j in range(3):
            A[i, j] = (3.0 if i == j else 0.0) - A[i, j]
    matmul_into(R, A, B)
    for i in range(3):
        for j in range(3):
            R[i, j] = 0.5 * B[i, j]


@cycle_kernel
def fk_kernel(k, lengths, p, R, limits, res, info, work):  # pragma: no cover - compiled
    """Levenberg-Marquardt FK; ``p``/``R`` hold the warm start in and the pose out;
    ``info`` receives [RMS residual (m), iterations, FKStatus]: a converged least-squares pose
    whose RMS residual is above ``max_residual`` (m) is INCONSISTENT. ``k``: the
    :class:`KinArrays` the iteration's IK writes into; ``work``: an ``FKWork`` (``fk_work``)."""
    m = lengths.shape[0]
    free_len, length, W = k[7], k[9], k[10]  # KinArrays: free_len, length, W
    tol, step_tol, max_iter, max_residual = limits
    if not _finite_input(lengths, p, R):
        info[0], info[1], info[2] = math.inf, 0.0, 3.0  # BAD_INPUT
        return
    lhs, rhs, L, y, step, p_new, R_new, E, A, B = work
    _polar_step(R, A, B)  # warm starts chain products off SO(3)
    ik_kernel(k, p, R)
    if not _lengths_ok(free_len):
        info[0], info[1], info[2] = math.inf, 0.0, 2.0  # DEGENERATE
        return
    cost = 0.0
    for i in range(m):
        res[i] = length[i] - lengths[i]
        cost += res[i] * res[i]
    mu = 1e-9  # Levenberg damping (m²); raised when a step does not reduce the residual
    it = 0
    while it < max_iter:
        if cost < tol * tol * m:
            _converged(info, math.sqrt(cost / m), it, max_residual)
            return
        it += 1
        _normal_equations(W, res, mu, lhs, rhs)
        if not _cholesky_solve6(lhs, rhs, L, y, step):
            info[0], info[1], info[2] = math.sqrt(cost / m), it, 2.0
            return
        p_new[0], p_new[1], p_new[2] = p[0] + step[0], p[1] + step[1], p[2] + step[2]
        _exp_left(step[3], step[4], step[5], R, E, R_new)
        big = 0.0
        for a in range(6):
            big = max(big, abs(step[a]))
        if big < step_tol:
            lin = _linearised_cost(W, res, step)
            copy_pose(p_new, R_new, p, R)
            _converged(info, math.sqrt(lin / m), it, max_residual)
            return
        ik_kernel(k, p_new, R_new)
        if not _lengths_ok(free_len):
            mu = mu * 100.0 + 1e-6
            ik_kernel(k, p, R)
            continue
        cost_new = _cost(length, lengths)
        if cost_new < cost:
            copy_pose(p_new, R_new, p, R)
            cost = cost_new
            for i in range(m):
                res[i] = length[i] - lengths[i]
            mu = max(mu * 0.1, 1e-12)
        else:
            mu = mu * 10.0 + 1e-9
            ik_kernel(k, p, R)
            if mu > 1e6:
                break
    rms = math.sqrt(cost / m)
    if rms < tol:
        _converged(info, rms, it, max_residual)
    else:
        info[0], info[1], info[2] = rms, it, 1.0  # MAX_ITERATIONS


@cycle_kernel
def _finite_input(lengths, p, R):  # pragma: no cover - compiled
    """Whether the measured lengths and the warm start hold no NaN nor infinity (their sum is
    finite: a NaN or an infinity anywhere makes it not)."""
    s = 0.0
    for i in range(lengths.shape[0]):
        s += lengths[i]
    s += p[0] + p[1] + p[2]
    for i in range(3):
        for j in range(3):
            s += R[i, j]
    return math.isfinite(s)


@cycle_kernel
def _normal_equations(W, res, mu, lhs, rhs):  # pragma: no cover - compiled
    """``lhs`` ← W Wᵀ + μ I and ``rhs`` ← W res: the damped Gauss-Newton system of the
    Levenberg-Marquardt step (``W`` the wrench matrix, 6 × m; ``res`` the length residuals, m;
    ``mu`` the damping, m²)."""
    m = res.shape[0]
    for a in range(6):
        acc = 0.0
        for i in range(m):
            acc += W[a, i] * res[i]
        rhs[a] = acc
        for b in range(a, 6):
            acc = 0.0
            for i in range(m):
                acc += W[a, i] * W[b, i]
            lhs[a, b] = acc
            lhs[b, a] = acc
        lhs[a, a] += mu


@cycle_kernel
def _linearised_cost(W, res, step):  # pragma: no cover - compiled
    """Σ residual² (m²) after ``step`` to first order: δl = −Wᵀ δX."""
    lin = 0.0
    for i in range(res.shape[0]):
        r_i = res[i]
        for a in range(6):
            r_i -= W[a, i] * step[a]
        lin += r_i * r_i
    return lin


@cycle_kernel
def _cost(length, lengths):  # pragma: no cover - compiled
    """Σ (l(X) − l_meas)² (m²): the squared length residuals of the pose ``length`` is of."""
    cost = 0.0
    for i in range(lengths.shape[0]):
        e = length[i] - lengths[i]
        cost += e * e
    return cost


@cycle_kernel
def _converged(info, rms, iterations, max_residual):  # pragma: no cover - compiled
    """``info`` of a converged solve: CONVERGED, or INCONSISTENT when the least-squares pose
    leaves an RMS residual above ``max_residual`` (m)."""
    info[0], info[1] = rms, iterations
    info[2] = 0.0 if rms <= max_residual else 4.0


@cycle_kernel
def _lengths_ok(free_len):  # pragma: no cover - compiled
    for x in free_len:  # noqa: SIM110 - numba compiles loops, not generators
        if not x > 1e-6:  # also False for NaN
            return False
    return True


def stretched_lengths(
    model: RobotModel, unstretched: FloatArray, tensions: FloatArray
) -> FloatArray:
    """Geometric lengths (m) of cables of unstretched lengths ``unstretched`` under ``tensions``.

    A winch measures the unstretched (paid-out) length; the forward kinematics needs the
    stretched one. Cable stretch ``t (l0 + l_w)/(E S)`` (or ``t/k`` for a fixed stiffness) plus
    the series spring's ``t/k_s``.
    """
    out = np.array(unstretched, dtype=np.float64)
    for i, c in enumerate(model.cables):
        out[i] += float(tensions[i]) * cable_compliance_py(*compliance_terms(c), out[i])
    return out
