"""Soft limits, one rule for every target (a path's samples, a jog's ray): the reference point
inside the workspace box, the tilt within ``max_angle``, and the wrench the cables must
exert there — the weight, the known external wrench and the motion's inertial load — held
with a tension margin of at least ``RobotModel.soft_margin`` (``cdprctl.tda.workspace``).
A motion that starts below that margin may go on while it does not lose more of it."""

from __future__ import annotations

import math

import numpy as np

from cdprctl.gripper import GripperSet
from cdprctl.model.robot import RobotModel
from cdprctl.motion.trajectory import coordinates_rotation
from cdprctl.rotation import FloatArray
from cdprctl.tda.workspace import Margins, hold_wrench


class SoftLimits:
    def __init__(self, model: RobotModel, external: FloatArray | None = None):
        self.model = model
        self.margins = Margins(model)
        self.grippers = GripperSet(model)
        self.external = np.asarray(
            model.control.external_wrench if external is None else external, dtype=float
        )
        self.required = model.soft_margin  # N

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
        self, coords: FloatArray, acceleration: FloatArray | None = None, floor: float | None = None
    ) -> tuple[FloatArray, FloatArray]:
        """For samples ``coords`` (n, 6): (margin N, ok bool) per sample; ``floor`` (N) lowers
        the required margin (a motion that starts below it). The box and the tilt are checked
        to 1 µm / 1 µrad."""
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
        return margin, ok

    def along(
        self, coords: FloatArray, acceleration: FloatArray | None = None
    ) -> tuple[FloatArray, FloatArray, float | None]:
        """``check`` of a motion's samples, from its first: a motion that starts below the
        required margin may go on while it loses none of it. Returns (margin, ok, the floor
        used or None)."""
        first = np.asarray(coords, dtype=float)[:1]
        margin, ok = self.check(first, None if acceleration is None else acceleration[:1])
        floor = None if ok[0] or not math.isfinite(margin[0]) else float(margin[0]) - 1e-6
        margin, ok = self.check(coords, acceleration, floor)
        return margin, ok, floor

    def why(self, coord: FloatArray, margin: float, floor: float | None = None) -> str:
        """Which rule the sample ``coord`` breaks, with the values and units."""
        ws = self.model.workspace
        p = coord[:3]
        for k, axis in enumerate("xyz"):
            if p[k] < ws.position_min[k] - 1e-6 or p[k] > ws.position_max[k] + 1e-6:
                return (f"{axis} = {p[k]:.4f} m is outside the workspace box "
                        f"[{ws.position_min[k]:g}, {ws.position_max[k]:g}] m")  # fmt: skip
        angle = float(np.linalg.norm(coord[3:]))
        if angle > ws.max_angle + 1e-6:
            return (f"the tilt {angle:.4f} rad from the home orientation exceeds "
                    f"workspace.max_angle = {ws.max_angle:g} rad")  # fmt: skip
        need = self.required if floor is None else min(self.required, floor)
        if not math.isfinite(margin):
            return "the cables' geometry is degenerate there (a cable of zero length)"
        return (
            f"the tension margin is {margin:.2f} N < {need:.2f} N required (the best "
            f"distribution comes that close to a tension limit; workspace.wrench_margin)"
        )

    def ray_end(
        self, start: FloatArray, direction: FloatArray, horizon: float, step: float = 0.005
    ) -> tuple[FloatArray, str]:
        """How far a straight motion from ``start`` along ``direction`` (6 coordinates, any
        scale) may go within the limits, up to ``horizon`` (in units of ``direction``):
        sampled every ``step`` m (or rad, for a rotation alone) then bisected to 1/64 of a
        step. Returns the end and what bounds it ("" when the horizon does)."""
        d = np.asarray(direction, dtype=float)
        scale = float(np.linalg.norm(d[:3])) or float(np.linalg.norm(d[3:]))
        if scale == 0.0:
            return np.array(start, dtype=float), "no direction"
        n = max(2, math.ceil(horizon * scale / step) + 1)
        s = np.linspace(0.0, horizon, n)
        coords = start[None, :] + s[:, None] * d[None, :]
        margin, ok, floor = self.along(coords)
        if ok.all():
            return coords[-1], ""
        bad = int(np.argmin(ok))
        if bad == 0:
            return np.array(start, dtype=float), self.why(coords[0], float(margin[0]), floor)
        lo, hi = s[bad - 1], s[bad]
        for _ in range(6):
            mid = 0.5 * (lo + hi)
            if self.check((start + mid * d)[None], floor=floor)[1][0]:
                lo = mid
            else:
                hi = mid
        return start + lo * d, self.why(coords[bad], float(margin[bad]), floor)
