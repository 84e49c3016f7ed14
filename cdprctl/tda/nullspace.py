"""Particular solution and null space of ``W t = w`` from one QR factorisation.

Picard et al. 2020, eq. (5): ``t = W⁺ w + N λ`` with ``N = null(W)``. With ``Wᵀ = Q R``
(``Q`` m×m orthogonal, ``R`` upper triangular in its first 6 rows):

* ``N = Q[:, 6:]`` — an orthonormal basis of ``null(W)`` (m × r);
* ``t0 = Q[:, :6] R₆⁻ᵀ w`` — the minimum-norm solution, equal to ``W⁺ w``; it lies in
  ``range(Wᵀ)``, so ``Nᵀ t0 = 0`` and ``‖t0 + N λ‖² = ‖t0‖² + ‖λ‖²``.

Householder QR in a numba kernel (~1 µs at 8×6): numpy's ``pinv`` costs 60-100 µs here and
LAPACK through scipy's wrappers ~16 µs, nearly all of it per-call overhead.
"""

from __future__ import annotations

import math

import numpy as np

from cdprctl.core.numerics import cycle_kernel, forward_substitution
from cdprctl.core.rotation import FloatArray


class NullSpace:
    """Workspace for an m-cable, 6-DOF wrench matrix."""

    def __init__(self, n_cables: int, dof: int = 6):
        self.m = n_cables
        self.dof = dof
        self.N = np.zeros((n_cables, n_cables - dof))  # orthonormal basis of null(W)
        self.t0 = np.zeros(n_cables)  # N, minimum-norm solution of W t = w
        self.rank_ok = False
        self.condition = math.inf  # ratio of the largest to smallest |R_ii|, a rank indicator
        self._Q = np.zeros((n_cables, n_cables))
        self._A = np.zeros((n_cables, dof))
        self._info = np.zeros(1)
        self._v = np.zeros(n_cables)  # the kernels' scratch: a reflector, then R⁻ᵀ w

    def update(self, W: FloatArray, w: FloatArray, rcond: float = 1e-10) -> bool:
        """Factorise ``W`` (6×m) and solve for ``w`` (6,). Returns False when ``W`` is
        (numerically) rank deficient or not finite; ``N`` and ``t0`` are then not valid."""
        ok = nullspace_kernel(W, w, rcond, self._A, self._Q, self.N, self.t0, self._info, self._v)
        self.rank_ok = bool(ok)
        self.condition = self._info.item(0) if ok else math.inf  # a float, not a numpy scalar
        return self.rank_ok

    def particular(self, w: FloatArray, out: FloatArray) -> None:
        """``out`` (m,) ← ``W⁺ w`` for another wrench ``w`` (6,) with the factorisation of the
        last :meth:`update` (which must have succeeded)."""
        particular_kernel(self._A, self._Q, w, out, self._v)


@cycle_kernel
def particular_kernel(A, Q, w, out, scratch):  # pragma: no cover - compiled
    """``out = Q₆ R₆⁻ᵀ w`` from ``nullspace_kernel``'s factorisation (``A`` holds ``R``):
    ``Rᵀ y = w`` by forward substitution, then ``Q₆ y`` (``y``: the first d of ``scratch``)."""
    d = A.shape[1]
    y = scratch[:d]
    forward_substitution(A.T, w, y)
    for i in range(out.shape[0]):
        s = 0.0
        for j in range(d):
            s += Q[i, j] * y[j]
        out[i] = s


@cycle_kernel
def nullspace_kernel(W, w, rcond, A, Q, N, t0, info, v):  # pragma: no cover - compiled
    """``v`` (m,): scratch, the Householder reflector (no array built in the loop)."""
    d, m = W.shape
    for i in range(m):
        for j in range(d):
            A[i, j] = W[j, i]
        for j in range(m):
            Q[i, j] = 1.0 if i == j else 0.0
    for j in range(d):
        s = 0.0
        for i in range(j, m):
            s += A[i, j] * A[i, j]
        nrm = math.sqrt(s)
        if not nrm > 0.0:  # zero column (or NaN): rank deficient, reported below
            continue
        alpha = -nrm if A[j, j] >= 0.0 else nrm
        vv = 0.0
        for i in range(j, m):
            v[i] = A[i, j]
        v[j] -= alpha
        for i in range(j, m):
            vv += v[i] * v[i]
        if vv == 0.0:
            continue
        for c in range(j, d):  # A ← H A
            dot = 0.0
            for i in range(j, m):
                dot += v[i] * A[i, c]
            f = 2.0 * dot / vv
            for i in range(j, m):
                A[i, c] -= f * v[i]
        for r in range(m):  # Q ← Q H
            dot = 0.0
            for i in range(j, m):
                dot += Q[r, i] * v[i]
            f = 2.0 * dot / vv
            for i in range(j, m):
                Q[r, i] -= f * v[i]
    dmin = math.inf
    dmax = 0.0
    for j in range(d):
        a = abs(A[j, j])
        dmin = min(dmin, a)
        dmax = max(dmax, a)
    if not (dmin > rcond * dmax and dmax < math.inf):  # False for NaN too
        return False
    info[0] = dmax / dmin
    particular_kernel(A, Q, w, t0, v)
    for i in range(m):
        for j in range(m - d):
            N[i, j] = Q[i, d + j]
    return math.isfinite(t0.sum())
