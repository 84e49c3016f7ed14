"""Forward kinematics: the platform pose from measured cable lengths.

Levenberg-Marquardt on the inverse kinematics (:mod:`cdprctl.kinematics`), warm-started from the
previous pose. The length Jacobian is ``∂l/∂X = −Wᵀ`` for a displacement screw
``δX = [δp, δφ]`` (rotation vector applied on the left), so each step solves
``(W Wᵀ + μ I) δX = W (l(X) − l_meas)``. The call never raises: failures are a status.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg.lapack import dposv as _dposv

from cdprctl.kinematics import KinematicsData, inverse_kinematics, kinematics_ok
from cdprctl.rotation import FloatArray, exp_so3, orthonormalize

if TYPE_CHECKING:
    from cdprctl.model.robot import RobotModel


class FKStatus(enum.IntEnum):
    CONVERGED = 0
    MAX_ITERATIONS = 1  # best pose returned, residual above tolerance
    DEGENERATE = 2  # a cable of zero length or a non-finite value on the way
    BAD_INPUT = 3  # non-finite measured lengths or start pose


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
    """

    REORTHONORMALIZE_EVERY = 64  # calls; products of exp(δφ) drift off SO(3) by ~1e-16 each

    def __init__(
        self,
        model: RobotModel,
        tolerance: float = 1e-9,
        step_tolerance: float = 1e-5,
        max_iterations: int = 30,
    ):
        self.model = model
        self.data = KinematicsData(model)
        self.tolerance = tolerance
        self.step_tolerance = step_tolerance
        self.max_iterations = max_iterations
        self._lhs = np.zeros((6, 6))
        self._rhs = np.zeros(6)
        self._res = np.zeros(model.n_cables)
        self._calls = 0

    def solve(
        self,
        lengths: FloatArray,
        position0: FloatArray,
        rotation0: FloatArray,
    ) -> FKResult:
        """Pose whose cable lengths (m, pulley arcs included) match ``lengths``.

        ``position0``/``rotation0`` is the warm start (the last pose, in the loop).
        """
        model, data = self.model, self.data
        p = np.array(position0, dtype=np.float64)
        R = np.array(rotation0, dtype=np.float64)
        # One reduction each: NaN and inf propagate through a sum.
        if not (math.isfinite(float(lengths.sum())) and math.isfinite(float(p.sum() + R.sum()))):
            return FKResult(p, R, math.inf, 0, FKStatus.BAD_INPUT)
        self._calls += 1
        if self._calls % self.REORTHONORMALIZE_EVERY == 0:
            R = orthonormalize(R)
        m = model.n_cables
        mu = 1e-9  # Levenberg damping (m²); raised when a step does not reduce the residual
        inverse_kinematics(model, data, p, R)
        if not kinematics_ok(data):
            return FKResult(p, R, math.inf, 0, FKStatus.DEGENERATE)
        res = np.subtract(data.length, lengths, out=self._res)
        cost = float(res @ res)
        iterations = 0
        lhs, rhs = self._lhs, self._rhs
        while iterations < self.max_iterations:
            if cost < self.tolerance * self.tolerance * m:
                return FKResult(p, R, math.sqrt(cost / m), iterations, FKStatus.CONVERGED)
            iterations += 1
            W = data.W
            np.dot(W, data.WT, out=lhs)
            lhs.flat[::7] += mu
            np.dot(W, res, out=rhs)
            # Cholesky through LAPACK directly: ~2 µs against ~10 µs for np.linalg.solve.
            _, step, info = _dposv(lhs, rhs)
            if info != 0:
                return FKResult(p, R, math.sqrt(cost / m), iterations, FKStatus.DEGENERATE)
            p_new = p + step[:3]
            R_new = exp_so3(step[3:]) @ R
            if float(np.abs(step).max()) < self.step_tolerance:
                lin = res - data.WT @ step  # l(X + δX) − l_meas to first order (δl = −Wᵀ δX)
                rms = math.sqrt(float(lin @ lin) / m)
                return FKResult(p_new, R_new, rms, iterations, FKStatus.CONVERGED)
            inverse_kinematics(model, data, p_new, R_new)
            if not kinematics_ok(data):
                mu = mu * 100.0 + 1e-6
                inverse_kinematics(model, data, p, R)
                continue
            res_new = data.length - lengths
            cost_new = float(res_new @ res_new)
            if cost_new < cost:
                p, R, cost = p_new, R_new, cost_new
                res[:] = res_new
                mu = max(mu * 0.1, 1e-12)
            else:
                mu = mu * 10.0 + 1e-9
                inverse_kinematics(model, data, p, R)
                if mu > 1e6:
                    break
        rms = math.sqrt(cost / m)
        status = FKStatus.CONVERGED if rms < self.tolerance else FKStatus.MAX_ITERATIONS
        return FKResult(p, R, rms, iterations, status)


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
        t = float(tensions[i])
        if c.stiffness is not None:
            out[i] += t / c.stiffness
        else:
            es = (c.youngs_modulus or 0.0) * (c.cross_section or 0.0)
            out[i] += t * (out[i] + c.length_to_winch) / es
        if c.spring_stiffness is not None:
            out[i] += t / c.spring_stiffness
    return out
