"""Soft limits, one rule for every target (a path's samples, a jog's ray): the reference point
inside the workspace box, the tilt within ``max_angle``, and the wrench the cables must
exert there — the weight, the known external wrench and the motion's inertial load — held
with a tension margin of at least ``RobotModel.soft_margin`` (``cdprctl.tda.workspace``), and
the cables at least ``[interference] clearance`` from each other, the platform's body and the
cell (``clearance.py``: at each sample, and between the samples of a motion). A motion that
starts below that margin, or under that clearance, may go on while it loses no more of it."""

from __future__ import annotations

import math

import numpy as np

from cdprctl.core.rotation import FloatArray, log_so3
from cdprctl.geometry.gripper_mechanics import GripperSet
from cdprctl.model.robot import RobotModel
from cdprctl.motion.clearance import Clearance
from cdprctl.motion.trajectory import coordinates_rotation
from cdprctl.tda.workspace import Margins, hold_wrench

#: m (or rad, a rotation alone): a straight move's line sampled this often (``line_refusal``)
LINE_STEP = 0.02
#: m: a move's target this close to its start's position is a rotation alone (``line_refusal``):
#: a tenth of a millimetre, finer than a position typed to 4 decimals, coarser than the
#: micrometres a robot at rest stands off the position it was sent to
SAME_POSITION = 1e-4
#: rad: and this close to its start's orientation, a translation alone (the same reasoning)
SAME_ORIENTATION = 1e-4


def angle_words(angle: float) -> str:
    """An angle (rad) as a refusal says it: degrees first, then radians."""
    return f"{math.degrees(angle):.2f}° ({angle:.4f} rad)"


def straight(coords: FloatArray) -> bool:
    """Whether the samples ``coords`` (n, 6) lie on the line from the first to the last
    (within 1 µm, 1 µrad): a move's, a one-segment path's."""
    d = coords[-1] - coords[0]
    dd = float(d @ d)
    if dd == 0.0:
        return True
    s = np.clip((coords - coords[0]) @ d / dd, 0.0, 1.0)
    return bool(np.max(np.abs(coords - coords[0] - s[:, None] * d)) <= 1e-6)


class SoftLimits:
    def __init__(self, model: RobotModel, external: FloatArray | None = None):
        self.model = model
        self.margins = Margins(model)
        self.grippers = GripperSet(model)
        self.external = np.asarray(
            model.control.external_wrench if external is None else external, dtype=float
        )
        self.required = model.soft_margin  # N
        self.clearance = Clearance(model)
        # m: the least distance of the last check's samples (with ``continuous``, of the way to
        # each), and (n, 6) the coordinates where it is
        self.nearest = np.full(1, math.inf)
        self.nearest_at = np.zeros((1, 6))
        self.near: float | None = None  # m: the last ``along``'s clearance floor

    def rotations(self, coords: FloatArray) -> FloatArray:
        """(n, 3, 3): the orientations of trajectory coordinates ``[p, φ]`` (φ: rotation
        vector from home, ``motion.trajectory``)."""
        home = self.model.home.rotation
        return np.array([coordinates_rotation(home, c[3:]) for c in coords])

    def wrenches(self, R: FloatArray, acceleration: FloatArray | None) -> FloatArray:
        """(n, 6) N, N·m at P: what the cables must exert at orientations ``R`` with the
        coordinates' accelerations (m/s², rad/s²; None: at rest)."""
        m, pf = self.model, self.model.platform
        out = np.empty((len(R), 6))
        for i, Ri in enumerate(R):
            out[i] = hold_wrench(m, Ri, self.external, self.grippers)
            if acceleration is not None:
                out[i, :3] += pf.mass * acceleration[i, :3]
                out[i, 3:] += Ri @ pf.inertia @ Ri.T @ acceleration[i, 3:]
        return out

    def check(
        self,
        coords: FloatArray,
        acceleration: FloatArray | None = None,
        floor: float | None = None,
        continuous: bool = False,
        near: float | None = None,
        clearance: bool = True,
    ) -> tuple[FloatArray, FloatArray]:
        """For samples ``coords`` (n, 6): (margin N, ok bool) per sample; ``floor`` (N) lowers
        the required margin (a motion that starts below it); ``near`` (m, not None: a motion
        that starts under the clearance, ``near_of``): each check under it at the start may go
        no closer than it was, the others keep the clearance; ``continuous``: the samples are
        one motion, checked between them too (``Clearance.least``); ``clearance`` False: the
        box, the tilt and the tensions only. The box and the tilt are checked to 1 µm /
        1 µrad."""
        c = np.asarray(coords, dtype=float).reshape(-1, 6)
        ws = self.model.workspace
        if acceleration is None and len(c) > 1 and not np.ptp(c[:, 3:], axis=0).any():
            # one orientation at rest (a translation): one rotation, one wrench
            R1 = self.rotations(c[:1])
            R = np.broadcast_to(R1, (len(c), 3, 3))
            w = np.broadcast_to(self.wrenches(R1, None), (len(c), 6))
        else:
            R = self.rotations(c)
            w = self.wrenches(R, acceleration)
        margin = self.margins.of(c[:, :3], R, w)
        need = self.required if floor is None else min(self.required, floor)
        ok = (
            np.all(c[:, :3] >= ws.position_min - 1e-6, axis=1)
            & np.all(c[:, :3] <= ws.position_max + 1e-6, axis=1)
            & (np.linalg.norm(c[:, 3:], axis=1) <= ws.max_angle + 1e-6)
            & (margin >= need)
        )
        if self.clearance.active and clearance:
            self.clearance.use_slack(near is not None)
            self.nearest, self.nearest_at = self.clearance.least(c, continuous)
            ok &= self.nearest >= self.clearance.limit
        else:
            self.nearest, self.nearest_at = np.full(len(c), math.inf), c
        return margin, ok

    def near_of(self, start: FloatArray, end: FloatArray | None = None) -> float | None:
        """A motion from the coordinates ``start``: None when it starts clear (the configured
        clearance everywhere), else its least distance there (m), each check under the
        clearance then kept no closer than it starts (``Clearance.relax_from``; in force in
        ``check`` and ``why`` given this as ``near``); a straight motion whose ``end`` is the
        home pose, no closer than home is either."""
        if not self.clearance.active:
            return None
        end = None if end is None else np.asarray(end, dtype=float).reshape(6)
        return self.clearance.relax_from(np.asarray(start, dtype=float).reshape(6), end)

    def along(
        self, coords: FloatArray, acceleration: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray, float | None]:
        """``check`` of a motion's samples, from its first, between the samples too: a motion
        that starts below the required margin, or under the clearance, may go on while it
        loses none of it. Returns (margin, ok, the floor used or None); the clearance's floor
        is kept in ``near``, ``nearest`` and ``nearest_at`` say where each sample's way came
        closest."""
        first = np.asarray(coords, dtype=float)[:1]
        margin, ok = self.check(first, None if acceleration is None else acceleration[:1])
        floor = None if margin[0] >= self.required or not math.isfinite(margin[0]) else (
            float(margin[0]) - 1e-6)  # fmt: skip
        c = np.asarray(coords, dtype=float)
        # the home pose's floor for a straight motion home only (a move, a one-segment path):
        # a path that ends at home goes elsewhere on its way, where its start's floor holds
        self.near = self.near_of(first[0], c[-1] if straight(c) else None)
        self.nearest_at = np.array(coords, dtype=float)  # (a check without the clearance)
        margin, ok = self.check(coords, acceleration, floor, continuous=True, near=self.near)
        return margin, ok, floor

    def why(
        self,
        coord: FloatArray,
        margin: float,
        floor: float | None = None,
        at: FloatArray | None = None,
        near: float | None = None,
        clearance: bool = True,
    ) -> str:
        """Which rule the sample ``coord`` breaks, with the values and units; ``at``: where the
        way to it came closest (``nearest_at``); ``near``, ``clearance`` as ``check`` took
        them."""
        outside = self.outside(coord)
        if outside:
            return outside
        if self.clearance.active and clearance:
            self.clearance.use_slack(near is not None)
            for x in (coord,) if at is None else (coord, at):
                if self.clearance.least(x)[0][0] < self.clearance.limit:
                    where = "" if x is coord else self._on_the_way(x)
                    return f"{where}{self.clearance.describe(x)} ([interference] clearance)"
        need = self.required if floor is None else min(self.required, floor)
        if not math.isfinite(margin):
            return "the cables' geometry is degenerate there (a cable of zero length)"
        return (
            f"the tension margin is {margin:.2f} N < {need:.2f} N required (the best "
            f"distribution comes that close to a tension limit; workspace.wrench_margin)"
        )

    def outside(self, coord: FloatArray) -> str:
        """Why the coordinates ``coord`` are outside the workspace box or beyond its tilt
        (to 1 µm / 1 µrad, as ``check``), or "" when inside."""
        ws = self.model.workspace
        p = coord[:3]
        for k, axis in enumerate("xyz"):
            if p[k] < ws.position_min[k] - 1e-6 or p[k] > ws.position_max[k] + 1e-6:
                return (f"{axis} = {p[k]:.4f} m is outside the workspace box "
                        f"[{ws.position_min[k]:g}, {ws.position_max[k]:g}] m")  # fmt: skip
        angle = float(np.linalg.norm(coord[3:]))
        if angle > ws.max_angle + 1e-6:
            return (f"the tilt {angle_words(angle)} from the home orientation exceeds "
                    f"workspace.max_angle = {ws.max_angle:g} rad "
                    f"({math.degrees(ws.max_angle):.2f}°)")  # fmt: skip
        return ""

    @staticmethod
    def _on_the_way(x: FloatArray) -> str:
        """Where between two samples the way came closest: the position and, turned, the
        tilt (a rotation alone stays at one position)."""
        tilt = float(np.linalg.norm(x[3:]))
        turned = f" turned {angle_words(tilt)} from the home orientation" if tilt else ""
        return f"on the way to it, at {np.round(x[:3], 4).tolist()} m{turned}, "

    def ray_end(
        self, start: FloatArray, direction: FloatArray, horizon: float, step: float = 0.005
    ) -> tuple[FloatArray, str]:
        """How far a straight motion from ``start`` along ``direction`` (6 coordinates, any
        scale) may go within the limits, up to ``horizon`` (in units of ``direction``):
        sampled every ``step`` m of its translation or ``step`` rad of its rotation, whichever
        needs more samples (a turn with a small translation is sampled as a turn), then
        bisected to 1/64 of a step. Returns the end and what bounds it there, with its value
        just past the end ("" when the horizon does)."""
        d = np.asarray(direction, dtype=float)
        scale = max(float(np.linalg.norm(d[:3])), float(np.linalg.norm(d[3:])))
        if scale == 0.0:
            return np.array(start, dtype=float), "no direction"
        n = max(2, math.ceil(horizon * scale / step) + 1)
        s = np.linspace(0.0, horizon, n)
        coords = start[None, :] + s[:, None] * d[None, :]
        margin, ok, floor = self.along(coords)
        near = self.near
        if ok.all():
            return coords[-1], ""
        bad = int(np.argmin(ok))
        if bad == 0:
            why = self.why(coords[0], float(margin[0]), floor, self.nearest_at[0], near)
            return np.array(start, dtype=float), why
        first = (coords[bad], float(margin[bad]), self.nearest_at[bad].copy())  # if all else fails
        lo, hi = s[bad - 1], s[bad]
        for _ in range(6):
            mid = 0.5 * (lo + hi)
            way = np.array([start + lo * d, start + mid * d])
            if self.check(way, floor=floor, continuous=True, near=near)[1].all():
                lo = mid
            else:
                hi = mid
        # what breaks just past the end, not at the sample first found (a step further on)
        way = np.array([start + lo * d, start + hi * d])
        margin, ok = self.check(way, floor=floor, continuous=True, near=near)
        if ok[1]:  # the bisection's resolution: the sample first found says why
            return start + lo * d, self.why(first[0], first[1], floor, first[2], near)
        return start + lo * d, self.why(way[1], float(margin[1]), floor, self.nearest_at[1], near)

    def line_refusal(self, start: FloatArray, target: FloatArray) -> str:
        """Why the straight line from the coordinates ``start`` to ``target`` (a move's, at
        rest at both ends) leaves the soft limits, with where and the rule broken, or "":
        ``ray_end`` sampled every ``LINE_STEP``. The one rule of a move's line: the gateway
        refuses with it before replying, the command desk keeps it as the last guard. Where
        the move turns, it says the rotation refused (its angle and axis from the start) and
        how much of it the limits allow; a rotation alone is named as one, not by the
        position it stays at."""
        start = np.array(start, dtype=float)  # a copy: the loop moves a reference it is given
        target = np.asarray(target, dtype=float)
        end, why = self.ray_end(start, target - start, 1.0, step=LINE_STEP)
        if not why:
            return ""
        where = np.round(end[:3], 4).tolist()
        turn = self._turn(start, target)
        angle = float(np.linalg.norm(turn))
        if angle <= SAME_ORIENTATION:
            return f"the line to the target leaves the soft limits after {where} m: {why}"
        allowed = angle_words(float(np.linalg.norm(self._turn(start, end))))
        if np.linalg.norm(target[:3] - start[:3]) <= SAME_POSITION:
            axis = np.round(turn / angle, 4).tolist()
            return (f"the rotation to the target, {angle_words(angle)} about {axis} (base frame) "
                    f"at {where} m, leaves the soft limits after {allowed}: {why}")  # fmt: skip
        return (f"the line to the target leaves the soft limits after {where} m and {allowed} "
                f"of its {angle_words(angle)} rotation: {why}")  # fmt: skip

    def _turn(self, a: FloatArray, b: FloatArray) -> FloatArray:
        """rad: the rotation vector (base frame) from the orientation of the coordinates
        ``a`` to that of ``b``."""
        Ra, Rb = self.rotations(np.array([a, b]))
        return log_so3(Rb @ Ra.T)
