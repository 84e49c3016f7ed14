"""Energy-based tension distribution (Sensors 2019, 19, 3403, §2).

With ``t = B + A λ`` (eq. (5)-(7): ``B = t0``, ``A = N``) the elastic energy of cable ``i`` is
``U_i = (b_i + a_i·λ)²/(2 k_i)`` (eq. (8)), a quadratic form ``(λᵀP_iλ + Q_iᵀλ + R_i)/(2k_i)``
(eq. (9)-(12)); the total ``U = Σ U_i`` (eq. (13)-(14)). Imposing an energy, a tension or a
deformation on cable ``i`` fixes its tension (eq. (2)-(4)) and so restricts λ to the affine set
``a_i·λ = t_i* − b_i`` (eq. (24)): a line for r = 2, "whose direction is the eigenvector of the
non-null eigenvalue" (eq. (21)-(22)). Each imposition removes one free dimension; what remains
is searched for the minimum total energy, and the feasible energy range of every other cable is
reported (eq. (17)-(20): tension bounds as energy bounds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import quadprog  # at import: an import statement in a solve looked the module up each time

from cdprctl.core.rotation import FloatArray
from cdprctl.tda.polygon import feasible_polygon, min_quadratic


def cable_energies(t: FloatArray, k: FloatArray) -> FloatArray:
    """``U_i = t_i²/(2 k_i)`` (J) — Sensors 2019, eq. (4)."""
    return t * t / (2.0 * k)


def energy_quadratic_form(
    N: FloatArray, t0: FloatArray, k: FloatArray
) -> tuple[FloatArray, FloatArray, float]:
    """Total energy as ``U(λ) = ½(λᵀ P λ + Qᵀ λ + R)`` — Sensors 2019, eq. (14), with
    ``P = Σ P_i/k_i``, ``Q = Σ Q_i/k_i``, ``R = Σ R_i/k_i`` and ``P_i = a_i a_iᵀ``,
    ``Q_i = 2 b_i a_i``, ``R_i = b_i²`` (eq. (10)-(12))."""
    inv_k = 1.0 / k
    P = (N.T * inv_k) @ N
    Q = 2.0 * (N.T * inv_k) @ t0
    R = float(np.sum(t0 * t0 * inv_k))
    return P, Q, R


def energy_bounds(t_min: FloatArray, t_max: FloatArray, k: FloatArray) -> FloatArray:
    """(m, 2) energy bounds (J) from the tension bounds — Sensors 2019, eq. (17)-(18)."""
    return np.stack([cable_energies(t_min, k), cable_energies(t_max, k)], axis=1)


@dataclass
class FreeSet:
    """``λ = λ_p + F μ`` after the impositions; ``F`` has orthonormal columns (r × f)."""

    lam_p: FloatArray
    F: FloatArray
    ok: bool


def impose(N: FloatArray, t0: FloatArray, cables: list[int], targets: list[float]) -> FreeSet:
    """Affine set of λ where cable ``cables[j]`` has tension ``targets[j]`` (Sensors 2019,
    eq. (24)). ``ok`` is False when the impositions are contradictory (dependent rows)."""
    r = N.shape[1]
    if not cables:
        return FreeSet(np.zeros(r), np.eye(r), True)
    A = N[cables]  # (q, r)
    b = np.asarray(targets) - t0[cables]
    q = len(cables)
    Q, Rm = np.linalg.qr(A.T, mode="complete")  # Aᵀ = Q R: A = R₁ᵀ Q₁ᵀ
    d = np.abs(np.diag(Rm[:q, :q]))
    if d.min() <= 1e-10 * max(1.0, d.max()):
        return FreeSet(np.zeros(r), np.zeros((r, 0)), False)
    y = np.linalg.solve(Rm[:q, :q].T, b)
    return FreeSet(Q[:, :q] @ y, Q[:, q:], True)


@dataclass
class EnergySolution:
    mu: FloatArray  # coordinates in the free set
    lam: FloatArray  # null-space coordinates
    feasible: bool
    t_range: FloatArray  # (m, 2) N, range of each cable's tension over the feasible free set
    polygon: list[tuple[float, float]]  # in μ coordinates, when 2 dimensions are free
    ends: FloatArray | None = None  # (2, m) N: tensions at the two ends, when 1 is free


def minimum_energy(
    N: FloatArray,
    t0: FloatArray,
    k: FloatArray,
    t_lo: FloatArray,
    t_hi: FloatArray,
    free: FreeSet,
) -> EnergySolution:
    """Minimum total energy (Sensors 2019, eq. (14)) over the feasible part of ``free``, and
    each cable's tension range there. Closed forms for 0, 1 and 2 free dimensions; a dense QP
    (quadprog) beyond, with the ranges then left as NaN."""
    m = N.shape[0]
    alpha = t0 + N @ free.lam_p  # tensions at μ = 0
    B = N @ free.F  # (m, f)
    f = B.shape[1]
    inv_k = 1.0 / k
    t_range = np.full((m, 2), math.nan)
    if f == 0:
        feasible = bool(np.all(alpha >= t_lo - 1e-9) and np.all(alpha <= t_hi + 1e-9))
        t_range[:, 0] = t_range[:, 1] = alpha
        return EnergySolution(np.zeros(0), free.lam_p.copy(), feasible, t_range, [])
    if f == 1:
        b = B[:, 0]
        lo, hi = -math.inf, math.inf
        feasible = True
        for i in range(m):
            bi = float(b[i])
            ai = float(alpha[i])
            if abs(bi) < 1e-12:
                if ai < t_lo[i] - 1e-9 or ai > t_hi[i] + 1e-9:
                    feasible = False
                continue
            e1, e2 = (t_lo[i] - ai) / bi, (t_hi[i] - ai) / bi
            lo = max(lo, min(e1, e2))
            hi = min(hi, max(e1, e2))
        if not feasible or lo > hi + 1e-12:
            return EnergySolution(np.zeros(1), free.lam_p.copy(), False, t_range, [])
        hi = max(hi, lo)
        # dU/dμ = Σ (α_i + b_i μ) b_i / k_i = 0
        mu = -float(np.sum(alpha * b * inv_k)) / float(np.sum(b * b * inv_k))
        mu = min(hi, max(lo, mu))
        ends = np.stack([alpha + b * lo, alpha + b * hi], axis=1)
        t_range[:] = np.sort(ends, axis=1)
        mu_v = np.array([mu])
        return EnergySolution(mu_v, free.lam_p + free.F @ mu_v, True, t_range, [], ends.T.copy())
    if f == 2:
        poly = feasible_polygon(B, alpha, t_lo, t_hi)
        if not poly:
            return EnergySolution(np.zeros(2), free.lam_p.copy(), False, t_range, [])
        H = (B.T * inv_k) @ B
        g = (B.T * inv_k) @ alpha
        x, y = min_quadratic(poly, H[0, 0], H[0, 1], H[1, 1], g[0], g[1])
        V = np.array(poly)
        tv = alpha[:, None] + B @ V.T  # (m, V)
        t_range[:, 0] = tv.min(axis=1)
        t_range[:, 1] = tv.max(axis=1)
        mu_v = np.array([x, y])
        return EnergySolution(mu_v, free.lam_p + free.F @ mu_v, True, t_range, poly)
    mu_qp = _qp_min_energy(B, alpha, inv_k, t_lo, t_hi)
    if mu_qp is None:
        return EnergySolution(np.zeros(f), free.lam_p.copy(), False, t_range, [])
    return EnergySolution(mu_qp, free.lam_p + free.F @ mu_qp, True, t_range, [])


def _qp_min_energy(
    B: FloatArray, alpha: FloatArray, inv_k: FloatArray, t_lo: FloatArray, t_hi: FloatArray
) -> FloatArray | None:
    H = (B.T * inv_k) @ B
    g = (B.T * inv_k) @ alpha
    C = np.hstack([B.T, -B.T])
    bvec = np.concatenate([t_lo - alpha, alpha - t_hi])
    try:
        return np.asarray(quadprog.solve_qp(H, -g, C, bvec, 0)[0])
    except ValueError:  # "constraints are inconsistent"
        return None
