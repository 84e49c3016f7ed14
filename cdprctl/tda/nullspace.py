"""Particular solution and null space of ``W t = w`` from one QR factorisation.

Picard et al. 2020, eq. (5): ``t = W⁺ w + N λ`` with ``N = null(W)``. With ``Wᵀ = Q R``
(``Q`` m×m orthogonal, ``R`` upper triangular in its first 6 rows):

* ``N = Q[:, 6:]`` — an orthonormal basis of ``null(W)`` (m × r);
* ``t0 = Q[:, :6] R₆⁻ᵀ w`` — the minimum-norm solution, equal to ``W⁺ w``; it lies in
  ``range(Wᵀ)``, so ``Nᵀ t0 = 0`` and ``‖t0 + N λ‖² = ‖t0‖² + ‖λ‖²``.

LAPACK is called directly (``dgeqrf``/``dorgqr``/``dtrtrs``, ~2 µs each here): numpy's
``pinv`` (SVD) costs 60-100 µs at 8×6, most of it per-call overhead.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.lapack import dgeqrf, dorgqr, dtrtrs

from cdprctl.rotation import FloatArray


class NullSpace:
    """Workspace for an m-cable, 6-DOF wrench matrix."""

    def __init__(self, n_cables: int, dof: int = 6):
        self.m = n_cables
        self.dof = dof
        self._a = np.zeros((n_cables, n_cables), order="F")
        self.N = np.zeros((n_cables, n_cables - dof))  # orthonormal basis of null(W)
        self.t0 = np.zeros(n_cables)  # N, minimum-norm solution of W t = w
        self.rank_ok = False
        self.condition = np.inf  # ratio of the largest to smallest |R_ii|, a rank indicator

    def update(self, W: FloatArray, w: FloatArray, rcond: float = 1e-10) -> bool:
        """Factorise ``W`` (6×m) and solve for ``w`` (6,). Returns False when ``W`` is
        (numerically) rank deficient or not finite; ``N`` and ``t0`` are then not valid."""
        d = self.dof
        a = self._a
        a[:, :d] = W.T
        a[:, d:] = 0.0
        qr, tau, _, info = dgeqrf(a, overwrite_a=1)
        if info != 0:
            self.rank_ok = False
            return False
        diag = [abs(float(qr[i, i])) for i in range(d)]
        dmin, dmax = min(diag), max(diag)
        if not dmin > rcond * dmax or dmax == np.inf:  # also False for NaN
            self.rank_ok = False
            self.condition = np.inf
            return False
        self.condition = dmax / dmin
        # R₆ᵀ y = w (lower triangular), then t0 = Q₆ y
        y, info = dtrtrs(qr[:d, :d], w, lower=0, trans=1)[:2]
        q, _, info2 = dorgqr(qr, tau, overwrite_a=1)
        if info != 0 or info2 != 0:
            self.rank_ok = False
            return False
        np.dot(q[:, :d], y, out=self.t0)
        self.N = q[:, d:]  # a view of this call's Q: no copy
        self.rank_ok = True
        return True
