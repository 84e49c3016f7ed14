"""The energy method of :class:`~cdprctl.tda.solver.TensionDistributor` (Sensors 2019, 19,
3403, §2: impositions on cables, eq. (24), then the minimum total energy, eq. (14)), with its
closed forms for r = 2 (one imposition: a segment; two: a point). A mixin: it works in the
distributor's workspace (null space, output, scratch)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from cdprctl.core.numerics import cycle_kernel
from cdprctl.core.rotation import FloatArray
from cdprctl.tda.energy import cable_energies, impose, minimum_energy
from cdprctl.tda.nullspace import NullSpace
from cdprctl.tda.types import (
    DEGENERATE,
    IMPOSITION_INFEASIBLE,
    OK,
    TDAOptions,
    TDAOutput,
    TDAStatus,
)

if TYPE_CHECKING:
    from cdprctl.model.robot import RobotModel


class EnergyMethod:
    # the distributor's, set in its __init__
    model: RobotModel
    r: int
    options: TDAOptions
    ns: NullSpace
    out: TDAOutput
    _f: FloatArray
    _lam2: FloatArray
    _no_free: FloatArray

    def _least_violating(self, lo: FloatArray, hi: FloatArray) -> TDAStatus:
        raise NotImplementedError  # the distributor's

    def _energy(
        self, lo: FloatArray, hi: FloatArray, k: FloatArray | None, t_prev: FloatArray | None
    ) -> TDAStatus:
        out, ns, opt = self.out, self.ns, self.options
        if k is None:
            out.message = "energy needs the cable stiffness k"
            return DEGENERATE
        cables = [imp.cable for imp in opt.impositions]
        targets = [imp.tension(float(k[imp.cable])) for imp in opt.impositions]
        if self.r == 2 and len(cables) == 1:
            fast = self._energy_line_r2(cables[0], targets[0], lo, hi, k)
            if fast is not None:
                return fast
        if self.r == 2 and len(cables) == 2:
            fast = self._energy_point_r2(cables, targets, lo, hi, k)
            if fast is not None:
                return fast
        free = impose(ns.N, ns.t0, cables, targets)
        sol = minimum_energy(ns.N, ns.t0, k, lo, hi, free) if free.ok else None
        status = OK
        if (sol is None or not sol.feasible) and free.ok:
            # Saturate: the last imposition clamped into the range the others leave it (a
            # planner ramping to the end of the range meets it there, not a jump to none)
            clamped = self._clamp_last(cables, targets, lo, hi, k)
            if clamped is not None:
                targets = clamped
                free = impose(ns.N, ns.t0, cables, targets)
                sol = minimum_energy(ns.N, ns.t0, k, lo, hi, free)
                if sol.feasible:
                    out.message = (
                        f"imposition on cable {self.model.cables[cables[-1]].name} saturated "
                        f"at {targets[-1]:.6g} N"
                    )
                    return self._energy_done(sol, free, cables, k, IMPOSITION_INFEASIBLE)
        if sol is None or not sol.feasible:
            # Keep the platform's wrench: drop the impositions, report why.
            unconstrained = impose(ns.N, ns.t0, [], [])
            sol = minimum_energy(ns.N, ns.t0, k, lo, hi, unconstrained)
            out.message = "impositions unreachable within the tension limits: dropped"
            if not sol.feasible:
                return self._least_violating(lo, hi)
            status = IMPOSITION_INFEASIBLE
            out.free_directions = ns.N.copy()
            return self._energy_done(sol, None, cables, k, status)
        return self._energy_done(sol, free, cables, k, status)

    def _clamp_last(
        self, cables: list[int], targets: list[float], lo: FloatArray, hi: FloatArray, k: FloatArray
    ) -> list[float] | None:
        """``targets`` with the last one clamped into the tension range (N) the other
        impositions leave its cable (Sensors 2019 eq. (17)-(20)); None if they leave none."""
        ns = self.ns
        free = impose(ns.N, ns.t0, cables[:-1], targets[:-1])
        if not free.ok:
            return None
        sol = minimum_energy(ns.N, ns.t0, k, lo, hi, free)
        rng = sol.t_range[cables[-1]]
        if not sol.feasible or not np.all(np.isfinite(rng)):
            return None
        return [*targets[:-1], min(max(targets[-1], float(rng[0])), float(rng[1]))]

    def _energy_done(
        self, sol: Any, free: Any, cables: list[int], k: FloatArray, status: TDAStatus
    ) -> TDAStatus:
        out, ns = self.out, self.ns
        if free is not None:
            out.free_directions = ns.N @ free.F
            out.polygon = np.array(sol.polygon).reshape(-1, 2)
        out.lam[:] = sol.lam
        out.tensions[:] = ns.t0 + ns.N @ sol.lam
        if sol.ends is not None:
            out.segment_ends[:] = sol.ends
        ranges = sol.t_range
        e = cable_energies(ranges, k[:, None])
        e[cables] = math.nan  # imposed cables have no range
        out.energy_range[:] = e
        return status

    def _energy_line_r2(
        self, c: int, target: float, lo: FloatArray, hi: FloatArray, k: FloatArray
    ) -> TDAStatus | None:
        """Sensors 2019 eq. (24) for r = 2 and one imposition, in closed form (see
        :func:`energy_line_kernel`). ``None`` when infeasible (the general path reports it)."""
        out, ns = self.out, self.ns
        ok = energy_line_kernel(
            ns.N,
            ns.t0,
            c,
            target,
            lo,
            hi,
            k,
            out.lam,
            out.tensions,
            out.segment_ends,
            out.energy_range,
            self._f,
        )
        if not ok:
            return None
        out.free_directions = ns.N @ self._f[:, None]
        return OK

    def _energy_point_r2(
        self, cables: list[int], targets: list[float], lo: FloatArray, hi: FloatArray, k: FloatArray
    ) -> TDAStatus | None:
        """Two impositions for r = 2 (Sensors 2019 §3.2: δ_8A imposed, cable 1A's energy set):
        eq. (24) twice leaves one point, ``a_i·λ = t_i* − b_i``, a 2×2 solve. ``None`` when
        the rows are dependent or the point breaks a limit (the general path reports it)."""
        out, ns = self.out, self.ns
        A = ns.N[cables]
        det = float(A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0])
        if abs(det) <= 1e-10 * max(1.0, float(np.abs(A).max()) ** 2):
            return None
        b0 = targets[0] - float(ns.t0[cables[0]])
        b1 = targets[1] - float(ns.t0[cables[1]])
        lam = self._lam2
        lam[0] = (A[1, 1] * b0 - A[0, 1] * b1) / det
        lam[1] = (A[0, 0] * b1 - A[1, 0] * b0) / det
        t = ns.t0 + ns.N @ lam
        if np.any(t < lo - 1e-9) or np.any(t > hi + 1e-9):
            return None
        out.lam[:] = lam
        out.tensions[:] = t
        out.free_directions = self._no_free
        out.segment_ends[:] = math.nan
        e = t * t / (2.0 * k)  # the point's energies: each free cable's range is one value
        e[cables] = math.nan
        out.energy_range[:, 0] = e
        out.energy_range[:, 1] = e
        return OK


@cycle_kernel
def energy_line_kernel(
    N, t0, c, target, lo, hi, k, lam, t, ends, erange, f
):  # pragma: no cover - compiled
    """Sensors 2019 eq. (24), r = 2, one imposed cable ``c`` at tension ``target`` (N): the
    line ``N_c·λ = target − t0_c`` is ``λ = λ_p + μ f``; each cable bounds μ to an interval,
    the total energy (eq. (14)) is a parabola in μ, minimised on it. Fills ``lam``, ``t``,
    the segment ``ends`` (2, m) and each cable's energy range ``erange`` (m, 2) (NaN for
    ``c``); returns False when the line misses the feasible set."""
    m = N.shape[0]
    a0, a1 = N[c, 0], N[c, 1]
    a2 = a0 * a0 + a1 * a1
    if a2 < 1e-20 or not (lo[c] - 1e-9 <= target <= hi[c] + 1e-9):
        return False
    s = (target - t0[c]) / a2
    lp0, lp1 = a0 * s, a1 * s
    na = math.sqrt(a2)
    f[0], f[1] = -a1 / na, a0 / na
    mu_lo, mu_hi = -math.inf, math.inf
    num = den = 0.0
    for i in range(m):
        alpha = t0[i] + N[i, 0] * lp0 + N[i, 1] * lp1
        beta = N[i, 0] * f[0] + N[i, 1] * f[1]
        if i == c:
            beta = 0.0
        ends[0, i], ends[1, i] = alpha, beta  # stash α, β
        num += alpha * beta / k[i]
        den += beta * beta / k[i]
        if i == c or abs(beta) < 1e-15:
            if not (lo[i] - 1e-9 <= alpha <= hi[i] + 1e-9):
                return False
            continue
        e1, e2 = (lo[i] - alpha) / beta, (hi[i] - alpha) / beta
        mu_lo = max(mu_lo, min(e1, e2))
        mu_hi = min(mu_hi, max(e1, e2))
    if not mu_lo <= mu_hi:
        return False
    mu = -num / den if den > 0.0 else 0.5 * (mu_lo + mu_hi)
    mu = min(mu_hi, max(mu_lo, mu))
    lam[0], lam[1] = lp0 + mu * f[0], lp1 + mu * f[1]
    for i in range(m):
        alpha, beta = ends[0, i], ends[1, i]
        t[i] = alpha + beta * mu
        e_lo, e_hi = alpha + beta * mu_lo, alpha + beta * mu_hi
        ends[0, i], ends[1, i] = e_lo, e_hi
        u1 = e_lo * e_lo / (2.0 * k[i])  # U = t²/(2k), Sensors 2019 eq. (4)
        u2 = e_hi * e_hi / (2.0 * k[i])
        erange[i, 0], erange[i, 1] = min(u1, u2), max(u1, u2)
    erange[c, 0] = erange[c, 1] = math.nan
    return True
