"""The wrench-feasible workspace: where the cables hold the platform's weight and a given
external wrench within their tension limits, and with how much to spare.

The *tension margin* of a pose (N) is how far the best distribution stays from the nearest
limit: ``max over t with W t = w of min_i min(t_i − t_min_i, t_max_i − t_i)``. The pose is
wrench-feasible when it is ≥ 0 (Gouttefarde and Gosselin 2006's wrench-feasible workspace,
for one wrench). With ``t = t0 + N λ`` (Picard et al. 2020, eq. (5)) it is minus the least
violation of the polygon's strips (``polygon.least_violating_kernel``): for r = 2 a compiled
2-D linear programme per point; for any other redundancy a linear programme in ``(t, s)``
solved by ``scipy.optimize.linprog`` (HiGHS), one per point.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.gripper_mechanics import GripperSet
from cdprctl.geometry.interference import Interference, interference_kernel
from cdprctl.geometry.kinematics import KinematicsData, ik_kernel
from cdprctl.model.robot import RobotModel
from cdprctl.tda.polygon import least_violating_kernel


def hold_wrench(
    model: RobotModel, R: FloatArray, external: FloatArray, grippers: GripperSet | None = None
) -> FloatArray:
    """The wrench (N, N·m at P, base frame) the cables must exert to hold the platform at rest
    at orientation ``R``: minus its weight, the jaws' weight and ``external`` (Picard et al.
    2020, eq. (1)). ``grippers``: the robot's, when the caller holds them already."""
    gs = grippers if grippers is not None else GripperSet(model)
    return -(model.gravity_wrench(R) + gs.weight_wrench(R) + np.asarray(external, dtype=float))


class Margins:
    """Tension margins (N) of many poses of one robot; ``-inf`` where the geometry is
    degenerate (a cable of zero length, a wrench matrix of rank < 6)."""

    def __init__(self, model: RobotModel):
        self.model = model
        self.kin = KinematicsData(model)
        self.lo = np.ascontiguousarray(model.tension_min, dtype=float)
        self.hi = np.ascontiguousarray(model.tension_max, dtype=float)
        self.method = "polygon" if model.redundancy == 2 else "lp"

    def of(self, positions: FloatArray, rotations: FloatArray, wrenches: FloatArray) -> FloatArray:
        """``positions`` (n, 3) m, ``rotations`` (n, 3, 3), ``wrenches`` (n, 6) the cables must
        exert (``hold_wrench`` plus any inertial load) → margins (n,) N."""
        P = np.ascontiguousarray(positions, dtype=float).reshape(-1, 3)
        R = np.ascontiguousarray(rotations, dtype=float).reshape(-1, 3, 3)
        w = np.ascontiguousarray(wrenches, dtype=float).reshape(-1, 6)
        out = np.empty(len(P))
        if self.method == "polygon":
            _margins_r2(self.kin.arrays, P, R, w, self.lo, self.hi, out)
        else:
            for i in range(len(P)):
                ik_kernel(self.kin.arrays, P[i], R[i])
                out[i] = margin_lp(self.kin.W, w[i], self.lo, self.hi)
        return out

    def at(self, position: FloatArray, R: FloatArray, wrench: FloatArray) -> float:
        """One pose's margin (N)."""
        return float(self.of(position[None], R[None], wrench[None])[0])


@njit(cache=True, nogil=True)  # a jog's or a path's check runs beside the loop's thread
def _margins_r2(k, P, R, w, lo, hi, out):  # pragma: no cover - compiled
    W = k[10]
    length = k[9]
    m = W.shape[1]
    anchors, attach = k[0], k[1]
    for n in range(P.shape[0]):
        ok = True
        for i in range(m):  # an attachment on its anchor: no direction (ik would divide by 0)
            d2 = 0.0
            for a in range(3):
                b = P[n, a] - anchors[i, a]
                for c in range(3):
                    b += R[n, a, c] * attach[i, c]
                d2 += b * b
            if not d2 > 1e-18:  # NaN too
                ok = False
        if ok:
            ik_kernel(k, P[n], R[n])
            for i in range(m):
                if not length[i] > 1e-9:
                    ok = False
        if not ok:
            out[n] = -math.inf
            continue
        U, S, Vt = np.linalg.svd(W)
        if S[5] <= 1e-9 * S[0]:
            out[n] = -math.inf
            continue
        N = np.ascontiguousarray(Vt[6:, :].T)
        y = (U.T @ w[n]) / S
        t0 = np.ascontiguousarray(Vt[:6, :]).T @ y
        _, _, s = least_violating_kernel(N, t0, lo, hi)
        out[n] = -s


def margin_lp(W: FloatArray, w: FloatArray, lo: FloatArray, hi: FloatArray) -> float:
    """The tension margin (N) as a linear programme in ``(t, s)``: maximise ``s`` subject to
    ``W t = w`` and ``lo + s <= t <= hi − s`` (HiGHS); ``-inf`` when ``W t = w`` has no
    solution at all."""
    from scipy.optimize import linprog

    m = W.shape[1]
    c = np.zeros(m + 1)
    c[-1] = -1.0
    eye = np.eye(m)
    ones = np.ones((m, 1))
    A_ub = np.vstack([np.hstack([eye, ones]), np.hstack([-eye, ones])])
    b_ub = np.concatenate([hi, -lo])
    A_eq = np.hstack([W, np.zeros((6, 1))])
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=w, bounds=(None, None),
                  method="highs")  # fmt: skip
    return float(-res.fun) if res.status == 0 else -math.inf


@dataclass(frozen=True)
class Grid:
    """A box of points, ``n[k]`` along each axis from ``lo[k]`` to ``hi[k]`` (m, base frame),
    in x-fastest order (then y, then z)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    n: tuple[int, int, int]

    def axes(self) -> list[FloatArray]:
        return [np.linspace(self.lo[k], self.hi[k], self.n[k]) for k in range(3)]

    def points(self) -> FloatArray:
        x, y, z = self.axes()
        Z, Y, X = np.meshgrid(z, y, x, indexing="ij")  # x varies fastest
        return np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)

    def cell_volume(self) -> float:
        """m³ per point: the spacing along each axis (an axis of one point counts 1 m, so a
        planar grid gives an area in m², a line a length)."""
        v = 1.0
        for k in range(3):
            if self.n[k] > 1:
                v *= (self.hi[k] - self.lo[k]) / (self.n[k] - 1)
        return v

    @property
    def measure_unit(self) -> str:
        """The unit of ``cell_volume``: m³, m² (a planar grid), m (a line), "" (one point)."""
        return ("", "m", "m²", "m³")[sum(1 for k in range(3) if self.n[k] > 1)]

    @staticmethod
    def parse(text: str) -> Grid:
        """``x0:x1:nx,y0:y1:ny,z0:z1:nz`` (m, counts); raises ValueError naming the part."""
        parts = text.split(",")
        if len(parts) != 3:
            raise ValueError(f"--grid = {text!r} must be x0:x1:nx,y0:y1:ny,z0:z1:nz")
        lo, hi, n = [], [], []
        for axis, part in zip("xyz", parts, strict=True):
            f = part.split(":")
            try:
                a, b, k = float(f[0]), float(f[1]), int(f[2])
                if len(f) != 3:
                    raise ValueError
            except (ValueError, IndexError):
                raise ValueError(
                    f"--grid {axis} = {part!r} must be start:stop:count (m, m, an integer)"
                ) from None
            if not (math.isfinite(a) and math.isfinite(b)) or b < a:
                raise ValueError(f"--grid {axis} = {part!r}: need finite start <= stop (m)")
            if not 1 <= k <= 400 or (k > 1 and b == a):
                raise ValueError(
                    f"--grid {axis} count = {k} must be in [1, 400] (and 1 when start = stop)"
                )
            lo.append(a)
            hi.append(b)
            n.append(k)
        return Grid((lo[0], lo[1], lo[2]), (hi[0], hi[1], hi[2]), (n[0], n[1], n[2]))

    @staticmethod
    def around(model: RobotModel, n: int = 20) -> Grid:
        """The box that holds the anchors and the configured workspace (a suspended robot's
        anchors all sit at the top: the workspace box gives the height), ``n`` points per
        axis."""
        ws = model.workspace
        lo = np.minimum(model.anchors.min(axis=0), ws.position_min)
        hi = np.maximum(model.anchors.max(axis=0), ws.position_max)
        return Grid(
            (float(lo[0]), float(lo[1]), float(lo[2])),
            (float(hi[0]), float(hi[1]), float(hi[2])),
            (n, n, n),
        )


@dataclass
class WorkspaceResult:
    grid: Grid
    points: FloatArray  # (n, 3) m, base frame, x fastest
    margin: FloatArray  # (n,) N; -inf where the geometry is degenerate
    seconds: float  # wall time of the margins
    method: str  # "polygon" (r = 2) or "lp"
    # the cables' least distance (m) at each point (``cdprctl/geometry/interference.py``), the check
    # that has it (an index of ``pairs``: what against what), the clearance (m), the time (s)
    clearance: FloatArray = field(default_factory=lambda: np.zeros(0))
    pair: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    pairs: list[str] = field(default_factory=list)
    limit: float = 0.0
    clearance_seconds: float = 0.0

    @property
    def feasible(self) -> np.ndarray:
        """Wrench-feasible: the tension margin ≥ 0."""
        return self.margin >= 0.0

    @property
    def clear(self) -> np.ndarray:
        """Interference-free: the cables at least the clearance apart (every point, with
        nothing to check)."""
        if not len(self.clearance):
            return np.ones(len(self.margin), dtype=bool)
        return self.clearance >= self.limit

    @property
    def usable(self) -> np.ndarray:
        """Both wrench-feasible and interference-free."""
        return self.feasible & self.clear

    @property
    def volume(self) -> float:
        """m³: feasible points × the grid's cell volume."""
        return float(np.count_nonzero(self.feasible)) * self.grid.cell_volume()

    @property
    def usable_volume(self) -> float:
        """m³: the points both wrench-feasible and interference-free × the cell volume."""
        return float(np.count_nonzero(self.usable)) * self.grid.cell_volume()


def wrench_feasible_workspace(
    model: RobotModel, grid: Grid, R: FloatArray, external: FloatArray
) -> WorkspaceResult:
    """The tension margin of every grid point at orientation ``R`` holding the weight plus the
    ``external`` wrench (N, N·m at P, base frame)."""
    pts = grid.points()
    n = len(pts)
    w = hold_wrench(model, R, external)
    calc = Margins(model)
    t0 = time.perf_counter()
    margin = calc.of(pts, np.broadcast_to(R, (n, 3, 3)), np.broadcast_to(w, (n, 6)))
    seconds = time.perf_counter() - t0
    g = Interference(model)
    res = WorkspaceResult(grid, pts, margin, seconds, calc.method, limit=g.clearance,
                          pairs=[g.name(c) for c in range(len(g.distance))])  # fmt: skip
    if len(g.distance):
        t0 = time.perf_counter()
        res.clearance, res.pair = np.empty(n), np.empty(n, dtype=np.int64)
        _clearances(calc.kin.arrays, pts, np.ascontiguousarray(R, dtype=float), g.arrays,
                    res.clearance, res.pair)  # fmt: skip
        res.clearance_seconds = time.perf_counter() - t0
    return res


@njit(cache=True, nogil=True)
def _clearances(k, P, R, g, out, which):  # pragma: no cover - compiled
    """The least distance (m) of every point ``P`` (n, 3) at the orientation ``R``, and its
    check (``interference_kernel``); NaN where the geometry is degenerate."""
    anchors, attach = k[0], k[1]
    distance, best = g[4], g[6]
    for n in range(P.shape[0]):
        ok = True
        for i in range(anchors.shape[0]):  # an attachment on its anchor: no cable
            d2 = 0.0
            for a in range(3):
                b = P[n, a] - anchors[i, a]
                for c in range(3):
                    b += R[a, c] * attach[i, c]
                d2 += b * b
            if not d2 > 1e-18:
                ok = False
        if not ok:
            out[n], which[n] = math.nan, 0
            continue
        ik_kernel(k, P[n], R)
        interference_kernel(k, P[n], R, g)
        out[n], which[n] = distance[best[0]], best[0]
