"""One interface for every tension distribution method.

``TensionDistributor(model, options)`` validates the options once (raising ``ValueError``
outside the loop); :meth:`TensionDistributor.solve` is the in-loop call: it never raises, and
a status other than ``OK`` comes with finite tensions that must not be applied as a solution
(least-violating ones for ``INFEASIBLE``; the previous tensions or ``t_min`` otherwise).

The cables must exert ``W t = w`` (``w``: the wrench the cables must apply to the platform,
N and N·m, base frame, moments about ``P``; in statics ``w = −(w_e + w_g)``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import quadprog  # at import: an import statement in a solve looked the module up each time

from cdprctl.core.numerics import cycle_kernel, kernel_args, total
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.kinematics import KinematicsData
from cdprctl.tda import planar
from cdprctl.tda import polygon as pg
from cdprctl.tda.energy_method import EnergyMethod
from cdprctl.tda.nullspace import NullSpace
from cdprctl.tda.types import (
    BARYCENTER,
    CLOSED_FORM,
    DEGENERATE,
    ENERGY,
    IMPOSITION_INFEASIBLE,
    INFEASIBLE,
    INTERNAL_ERROR,
    MIN_1NORM,
    MIN_2NORM,
    OK,
    OUT_OF_LIMITS,
    PINV,
    QP,
    SOTDA,
    TDAOptions,
    TDAOutput,
    TDAStatus,
)

if TYPE_CHECKING:
    from cdprctl.model.robot import RobotModel

_PLANAR_CODE = {
    BARYCENTER: planar.BARYCENTER,
    MIN_2NORM: planar.MIN_2NORM,
    MIN_1NORM: planar.MIN_1NORM,
    SOTDA: planar.SOTDA,
}
BOUND_TOLERANCE = 1e-6  # N: round-off accepted on a bound, then clipped onto it


class SolveInput:
    """One solve's inputs, set by ``solve`` into the distributor's own instance (allocated
    once: the loop builds no objects) and read by the methods it dispatches to."""

    __slots__ = ("W", "hi", "k", "kin", "lo", "t_prev", "w")

    def __init__(self, model: RobotModel):
        self.W: FloatArray = np.zeros((6, model.n_cables))  # the wrench matrix at the pose
        self.w: FloatArray = np.zeros(6)  # N, N·m: the wrench the tensions must produce
        self.lo: FloatArray = model.tension_min  # N, per cable
        self.hi: FloatArray = model.tension_max  # N, per cable
        self.k: FloatArray | None = None  # N/m, cable stiffness (energy, sotda)
        self.kin: KinematicsData | None = None  # the kinematics at the pose (sotda)
        self.t_prev: FloatArray | None = None  # N: the last tensions (the rate limit)


class TensionDistributor(EnergyMethod):
    """Tension distribution for one robot and one set of options."""

    def __init__(self, model: RobotModel, options: TDAOptions | None = None):
        self.model = model
        self.m = model.n_cables
        self.r = model.redundancy
        self.options = options or TDAOptions()
        errors = self.options.validate(model)
        if errors:
            raise ValueError("invalid TDA options: " + "; ".join(errors))
        self.ns = NullSpace(self.m)
        self.out = TDAOutput(self.m, self.r)
        self._f = np.zeros(2)
        self._lam2 = np.zeros(2)
        self._no_polygon = np.zeros((0, 2))
        self._no_free = np.zeros((self.m, 0))
        self._planar_work = planar.PlanarWork.of(self.m)
        self._planar = kernel_args(self._planar_work)  # the same arrays, as the kernel takes them
        self._verts = self._planar_work.verts
        # the polygon of each vertex count, a view each, built once: none per solve
        self._polygons = tuple(self._verts[:n] for n in range(len(self._verts) + 1))
        self._code_of: TDAOptions | None = None  # the options _planar_code is for
        self._planar_code = planar.BARYCENTER
        self._ones = np.ones(self.m)
        self._halves = np.full(self.m, 0.5)
        self._dt = self.options.period  # s, the rate limit's step of this solve
        self._no_kin = KinematicsData(model)  # placeholder geometry when no kinematics given
        self._direction = np.zeros(3)
        self._delta_wrench = np.zeros(6)
        self._in = SolveInput(model)
        self.set_options(self.options)

    def set_options(self, options: TDAOptions) -> None:
        """Use ``options`` from the next solve: the loop switches a distributor built at
        start-up this way, allocating nothing (but for SOTDA's grid finer than any before:
        its candidates' room, once). The options must have been validated for this robot
        (``TDAOptions.validate``)."""
        self.options = options
        grid = options.grid_points if options.sotda_variant == "grid" else 0
        work = self._planar_work
        if grid * grid + work.verts.shape[0] > work.cand.shape[0] - 1:  # a finer grid: once
            bigger = planar.PlanarWork.of(self.m, grid)
            self._planar_work = work._replace(cand=bigger.cand, dX=bigger.dX)
            self._planar = kernel_args(self._planar_work)
        d = options.direction
        n = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        for i in range(3):
            self._direction[i] = d[i] / n
        if options.delta_wrench is not None:
            for i in range(6):
                self._delta_wrench[i] = options.delta_wrench[i]
        else:
            self._delta_wrench[:3] = self._direction
            self._delta_wrench[3:] = 0.0

    # -- the in-loop call ---------------------------------------------------------------------
    def solve(
        self,
        W: FloatArray,
        wrench: FloatArray,
        t_min: FloatArray | None = None,
        t_max: FloatArray | None = None,
        k: FloatArray | None = None,
        kin: KinematicsData | None = None,
        t_prev: FloatArray | None = None,
        dt: float | None = None,
    ) -> TDAOutput:
        """Tensions (N) with ``W t = wrench`` inside ``[t_min, t_max]`` (defaults: the model's).

        ``k`` (N/m, cable stiffness) is needed by ``energy`` and ``sotda``, ``kin`` (the
        kinematics at the pose of ``W``) by ``sotda``; ``t_prev`` (N) enables the rate limit,
        over ``dt`` s since ``t_prev`` (default: the options' period).
        """
        out, i = self.out, self._in
        i.W, i.w, i.k, i.kin, i.t_prev = W, wrench, k, kin, t_prev
        i.lo = self.model.tension_min if t_min is None else t_min
        i.hi = self.model.tension_max if t_max is None else t_max
        out.rate_limited = False
        out.max_violation = 0.0
        out.message = ""
        out.polygon = self._no_polygon
        out.area = 0.0
        out.barycenter = (math.nan, math.nan)
        out.sotda_displacement = math.nan
        out.energy_total = math.nan
        if self.options.method is ENERGY:
            out.energy_range[:] = math.nan
            out.segment_ends[:] = math.nan
        if k is None:
            out.energies[:] = math.nan
        try:
            self._dt = dt if dt is not None else self.options.period
            status = self._solve()
        except Exception as exc:
            status = INTERNAL_ERROR
            out.message = f"{type(exc).__name__}: {exc}"
        return self._finish(status)

    # -- dispatch -----------------------------------------------------------------------------
    def _solve(self) -> TDAStatus:
        out, ns, method, i = self.out, self.ns, self.options.method, self._in
        W, w, lo, hi = i.W, i.w, i.lo, i.hi
        if not ns.update(W, w) or not math.isfinite(total(w)):
            out.message = "wrench matrix rank-deficient or non-finite input"
            return DEGENERATE
        if method is PINV:
            out.tensions[:] = ns.t0
            out.lam[:] = 0.0
            return OK
        if method is CLOSED_FORM:
            return self._closed_form(W, w, lo, hi)
        if method is ENERGY:
            return self._energy(lo, hi, i.k, i.t_prev)
        if method is QP or (method is MIN_2NORM and self.r != 2):
            return self._qp(lo, hi, np.zeros(self.r))
        return self._polygon_method()

    def _polygon_method(self) -> TDAStatus:
        """The r = 2 polygon methods in one compiled call (``planar.planar_kernel``)."""
        out, ns, opt, i = self.out, self.ns, self.options, self._in
        lo, hi, k, kin, t_prev = i.lo, i.hi, i.k, i.kin, i.t_prev
        sotda = opt.method is SOTDA
        if sotda and (k is None or kin is None):
            out.message = "sotda needs the cable stiffness k and the kinematics"
            return DEGENERATE
        info = self._planar_work.info
        kd = kin if kin is not None else self._no_kin
        rate = t_prev is not None and opt.max_tension_rate is not None
        if opt is not self._code_of:  # hashing the method (a Python __hash__) built an int
            self._code_of, self._planar_code = opt, _PLANAR_CODE.get(opt.method, planar.BARYCENTER)
        ok = planar.planar_kernel(
            self._planar_code,
            ns.N,
            ns.t0,
            lo,
            hi,
            k if k is not None else self._ones,
            kd.arrays,
            self._delta_wrench,
            self._direction,
            opt.nu,
            opt.grid_points if sotda and opt.sotda_variant == "grid" else 0,
            t_prev if rate else lo,
            (opt.max_tension_rate or 0.0) * self._dt if rate else math.inf,
            self._planar,
            out.lam,
            out.tensions,
        )
        if not ok:
            return self._least_violating(lo, hi)
        # item(): plain floats, not numpy scalars
        out.polygon = self._polygons[int(info.item(planar.NV))]
        out.area = info.item(planar.AREA)
        out.barycenter = (info.item(planar.BX), info.item(planar.BY))
        out.sotda_displacement = info.item(planar.SOTDA_DP)
        flag = int(info.item(planar.RATE_FLAG))
        if flag == 1:
            out.rate_limited = True
        elif flag == 2:
            out.message = "tension rate limit cannot hold the wrench: not applied"
        return OK

    def _least_violating(self, lo: FloatArray, hi: FloatArray) -> TDAStatus:
        out, ns = self.out, self.ns
        if self.r == 2:
            lam, s = pg.least_violating(ns.N, ns.t0, lo, hi)
            out.lam[:] = lam
            out.tensions[:] = ns.t0 + ns.N @ lam
        else:
            lam_opt = _qp_least_violating(ns.N, ns.t0, lo, hi)
            out.lam[:] = lam_opt
            out.tensions[:] = ns.t0 + ns.N @ lam_opt
            s = float(np.max(np.maximum(lo - out.tensions, out.tensions - hi)))
        out.max_violation = max(0.0, s)
        out.message = f"wrench infeasible: least-violating tensions, {s:.3g} N beyond a bound"
        return INFEASIBLE

    def _qp(self, lo: FloatArray, hi: FloatArray, lam_target: FloatArray) -> TDAStatus:
        """Nearest tensions to ``t0 + N lam_target`` within the bounds (a QP in λ: with
        orthonormal N, ``‖t − t_target‖ = ‖λ − lam_target‖``)."""
        ns, out = self.ns, self.out
        N, t0 = ns.N, ns.t0
        C = np.hstack([N.T, -N.T])
        b = np.concatenate([lo - t0, t0 - hi])
        try:
            lam = np.asarray(quadprog.solve_qp(np.eye(self.r), lam_target, C, b, 0)[0])
        except ValueError:
            return self._least_violating(lo, hi)
        out.lam[:] = lam
        out.tensions[:] = t0 + N @ lam
        return OK

    def _closed_form(
        self, W: FloatArray, w: FloatArray, lo: FloatArray, hi: FloatArray
    ) -> TDAStatus:
        """Pott's improved closed form (Pott 2014, Computational Kinematics, pp. 139-146):
        ``t = t_m + W⁺ (w − W t_m)`` with ``t_m`` the mid-range tensions; while a tension
        violates its bound, the most violating cable is fixed at that bound and removed, as
        long as at least 6 cables remain."""
        out = self.out
        t = 0.5 * (lo + hi)
        active = list(range(self.m))
        fixed = np.zeros(self.m, dtype=bool)
        while True:
            Wa = W[:, active]
            rest = w - W[:, fixed] @ t[fixed]
            tm = 0.5 * (lo[active] + hi[active])
            ta = tm + np.linalg.lstsq(Wa, rest - Wa @ tm, rcond=None)[0]
            t[active] = ta
            viol = np.maximum(lo[active] - ta, ta - hi[active])
            worst = int(np.argmax(viol))
            if viol[worst] <= BOUND_TOLERANCE:
                out.tensions[:] = t
                out.lam[:] = self.ns.N.T @ (t - self.ns.t0)
                return OK
            if len(active) <= 6:
                out.tensions[:] = t
                out.max_violation = float(viol[worst])
                out.message = "closed form: no feasible tensions found"
                return INFEASIBLE
            i = active.pop(worst)
            fixed[i] = True
            t[i] = lo[i] if ta[worst] < lo[i] else hi[i]

    # -- the guarantee ------------------------------------------------------------------------
    def _finish(self, status: TDAStatus) -> TDAOutput:
        out, i = self.out, self._in
        W, w, lo, hi, k, t_prev = i.W, i.w, i.lo, i.hi, i.k, i.t_prev
        t = out.tensions
        finite = math.isfinite(total(t))  # NaN and inf survive a sum
        if status in (DEGENERATE, INTERNAL_ERROR) or not finite:
            if status not in (DEGENERATE, INTERNAL_ERROR):
                status = INTERNAL_ERROR
                out.message = out.message or "non-finite tensions"
            fallback = t_prev if t_prev is not None and np.all(np.isfinite(t_prev)) else lo
            t[:] = np.clip(fallback, lo, hi)
            out.residual = math.inf
            out.status = status
            return out
        viol, residual = check_kernel(W, w, t, lo, hi)
        if status in (OK, IMPOSITION_INFEASIBLE):
            if viol > BOUND_TOLERANCE:
                status = (
                    OUT_OF_LIMITS
                    if self.options.method is PINV
                    else INFEASIBLE
                )
                out.max_violation = viol
            elif viol > 0.0:  # round-off: onto the bound
                np.maximum(t, lo, out=t)
                np.minimum(t, hi, out=t)
        out.residual = residual
        if k is not None:
            np.multiply(t, t, out=out.energies)
            out.energies /= k
            # U_i = t_i²/(2 k_i), Sensors 2019 eq. (4); by an array of halves: a scalar
            # operand built an array each call
            np.multiply(out.energies, self._halves, out=out.energies)
            out.energy_total = total(out.energies)
        out.status = status
        return out


def _qp_least_violating(
    N: FloatArray, t0: FloatArray, lo: FloatArray, hi: FloatArray
) -> FloatArray:
    """min s subject to lo − s <= t0 + N λ <= hi + s (a tiny regularisation makes it a QP)."""
    r = N.shape[1]
    G = np.eye(r + 1) * 1e-9
    a = np.zeros(r + 1)
    a[-1] = -1.0
    ones = np.ones((N.shape[0], 1))
    C = np.vstack([np.hstack([N, ones]), np.hstack([-N, ones])]).T
    b = np.concatenate([lo - t0, t0 - hi])
    x = np.asarray(quadprog.solve_qp(G, a, C, b, 0)[0])
    return x[:r]


@cycle_kernel
def check_kernel(W, w, t, lo, hi):  # pragma: no cover - compiled
    """(largest bound violation in N, ‖W t − w‖ / max(1, ‖w‖))."""
    viol = -math.inf
    for i in range(t.shape[0]):
        viol = max(viol, lo[i] - t[i], t[i] - hi[i])
    r2 = w2 = 0.0
    for a in range(W.shape[0]):
        s = -w[a]
        for i in range(t.shape[0]):
            s += W[a, i] * t[i]
        r2 += s * s
        w2 += w[a] * w[a]
    return viol, math.sqrt(r2) / max(1.0, math.sqrt(w2))
