"""The cables' clearance as a soft limit (issue 67): the least distance between two cables, a
cable and the platform's body, a cable and the cell, the body and the cell
(``cdprctl/geometry/interference.py``) at each sample of a motion, and between two samples.

Between samples the check does not trust the sampling step; it bounds what can happen there.
Every distance measured is 1-Lipschitz in the motion of the points it is measured between:
moving a segment's ends by at most ``δ`` moves each of its points by at most ``δ``, so the
distance between two segments (or a segment and a rigid body) changes by at most the sum of
their displacements. From one sample to the next, an attachment ``B_i = p + R b_i`` moves at
most ``|Δp| + |b_i| |Δφ|`` (``φ`` the rotation vector from home: the Jacobian of the
exponential map has singular values 1 and ``sinc(θ/2) ≤ 1``), the body's corners likewise; an
exit point on its swivel pulley moves by its chord (mm and less at a path's spacing). With
``Δ`` twice the largest of these, the distance between samples ``k−1`` and ``k`` is at least
``(d_{k−1} + d_k − Δ) / 2``. Where that bound falls under the clearance while both samples
are clear, the interval is bisected, linearly in the coordinates, each half by the same bound
(``Δ`` times its share), until every part is clear by it or its bound is under
``REFINE_STEP``: a dip left between two measured points is then under ``REFINE_STEP / 2``
(0.05 mm) — the guarantee of sampling the interval every ``REFINE_STEP``, for a few
measurements where that took ``Δ / REFINE_STEP`` (400 for a jog's 2 cm steps). Only
intervals near the clearance pay for it; a path's 2 mm spacing and a move's 2 cm steps need
no finer sampling of their own.
"""

from __future__ import annotations

import math

import numpy as np

from cdprctl.core.rotation import FloatArray, exp_so3
from cdprctl.geometry.interference import Interference, distance_words, relax_kernel
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel

#: m: the displacement bound of one refined sub-interval (what a dip there may hide: half)
REFINE_STEP = 1e-4
#: m: how far under its start a pair that starts under the clearance may be measured (the
#: start itself passes)
START_TOLERANCE = 1e-6
#: m, rad: a motion whose end is this near the home pose goes home (``relax_from``)
HOME_TOLERANCE = 1e-5


class Clearance:
    """The interference checks of ``model`` at trajectory coordinates ``[p, φ]`` (m, rad from
    the home orientation)."""

    def __init__(self, model: RobotModel):
        self.model = model
        self.interference = Interference(model)
        self.limit = self.interference.clearance  # m
        self.active = len(self.interference.distance) > 0
        self._kin = KinematicsData(model)
        self._home = model.home.rotation
        points = [np.asarray(model.attachments, dtype=float)]
        for box in self.interference.config.body:
            signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
            points.append(box.centre + (signs * box.half_extents) @ np.asarray(box.rotation).T)
        # m: the farthest a point of the platform (attachment, body corner) is from P
        self.radius = float(np.max(np.linalg.norm(np.vstack(points), axis=1)))
        # m per check: the slack of a motion that starts under the clearance (``relax_from``)
        self._slack = np.zeros(len(self.interference.distance))
        self.started = ""  # that start's closest pair and distance, in words ("": clear)
        # m per check: at the home pose, where a robot under the clearance may always come
        # back to (``relax_from``); and each check's floor, the lower of it and the start's
        n = len(self.interference.distance)
        self._home_x = np.r_[np.asarray(model.home.position, dtype=float), np.zeros(3)]
        self.home_distance = np.full(n, math.inf)  # m per check
        if self.active:
            self._measure(self._home_x)
            self.home_distance[:] = self.interference.distance
        self._floor_of = np.zeros(n)
        self._home_floor = np.zeros(n, dtype=bool)  # per check: its floor is the home pose's

    def relax_from(self, x: FloatArray, end: FloatArray | None = None) -> float | None:
        """A motion from the coordinates ``x`` (to ``end``, if known): each check under the
        clearance there may go on no closer than it is (``relax_kernel``), the others keep the
        clearance — taken by the measurements while ``use_slack(True)``. A motion that ends
        at the home pose may come as close as the robot is there: one that stands under the
        clearance at home (seed000's cable 2 at its cube) may always go back, and only there
        (a jog, or a motion elsewhere, keeps its start's floor: never deeper into a fixture
        than it is). Returns the least floor (m) when one is under the clearance, else None
        (nothing relaxed)."""
        g = self.interference
        g.slack.fill(0.0)
        self._slack.fill(0.0)
        if not self.active:
            self.started = ""
            return None
        home = end is not None and float(np.max(np.abs(end - self._home_x))) <= HOME_TOLERANCE
        d = self._measure(np.asarray(x, dtype=float))
        if home:
            np.less(self.home_distance, g.distance, out=self._home_floor)
            np.minimum(g.distance, self.home_distance, out=self._floor_of)
        else:
            self._home_floor.fill(False)
            self._floor_of[:] = g.distance
        least = float(self._floor_of.min())
        if least >= self.limit:
            self.started = ""
            return None
        self.started = g.describe() if d < self.limit else ""  # the start's, in words
        relax_kernel(self._floor_of, g.slack, self.limit + START_TOLERANCE,
                     self.limit + START_TOLERANCE)  # fmt: skip
        self._slack[:] = g.slack
        return least

    def use_slack(self, on: bool) -> None:
        """The last ``relax_from``'s slack in the measurements (``on``), or none."""
        if on:
            self.interference.slack[:] = self._slack
        else:
            self.interference.slack.fill(0.0)

    def at(self, coords: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(n,) the least distance (m) at each sample of ``coords`` (n, 6) and (n, m, 3) the
        exit points there (m, base frame)."""
        c = np.asarray(coords, dtype=float).reshape(-1, 6)
        dist = np.empty(len(c))
        exits = np.empty((len(c), self._kin.n_cables, 3))
        for k, x in enumerate(c):
            dist[k] = self._measure(x)
            exits[k] = self._kin.exitT.T
        return dist, exits

    def _measure(self, x: FloatArray) -> float:
        """m: the least distance at ``x``, each check's slack added (``Interference.effective``):
        under ``limit`` is too close."""
        inverse_kinematics(self.model, self._kin, x[:3], exp_so3(x[3:]) @ self._home)
        self.interference.update(self._kin)
        return self.interference.effective

    def least(self, coords: FloatArray, continuous: bool = False) -> tuple[FloatArray, FloatArray]:
        """(n,) m: the least distance at each sample of ``coords``, and (n, 6) the coordinates
        where it is. ``continuous``: the samples are one motion, and sample ``k`` also
        answers for the way from sample ``k − 1`` to it (the bound of the module's doc)."""
        c = np.asarray(coords, dtype=float).reshape(-1, 6)
        dist, exits = self.at(c)
        where = c.copy()
        if not continuous:
            return dist, where
        for k in range(1, len(c)):
            if min(dist[k - 1], dist[k]) < self.limit:
                continue  # a sample already fails there
            step = c[k] - c[k - 1]
            moved = float(np.linalg.norm(step[:3]) + self.radius * np.linalg.norm(step[3:]))
            chord = float(np.max(np.linalg.norm(exits[k] - exits[k - 1], axis=1)))
            bound = 2.0 * max(moved, chord)  # m: the most the distance changes between them
            d, s = self._dip(c[k - 1], step, dist[k - 1], dist[k], bound)
            if d < dist[k]:
                dist[k], where[k] = d, c[k - 1] + s * step
        return dist, where

    def _dip(self, start: FloatArray, step: FloatArray, d0: float, d1: float,
             bound: float) -> tuple[float, float]:  # fmt: skip
        """(m, fraction): the least distance found on ``start + s step``, ``s`` in [0, 1],
        whose ends are ``d0``, ``d1`` m clear and along which the distance changes by at most
        ``bound`` m. Bisection by the bound of the module's doc: a part ``[a, b]`` is at
        least ``(d_a + d_b − bound (b − a)) / 2``; it is split while that is under the limit
        (or under the least found) and its own bound is ``REFINE_STEP`` or more, so a dip
        left between two measured points is under ``REFINE_STEP / 2`` deep — as sampling
        the whole way every ``REFINE_STEP``, for a few measurements instead of
        ``bound / REFINE_STEP``."""
        if not math.isfinite(bound):  # no bound: nothing between the ends can be vouched for
            return math.nan, 0.5
        best, best_s = math.inf, 0.0
        parts = [(0.0, 1.0, d0, d1)]
        while parts:
            a, b, da, db = parts.pop()
            span = bound * (b - a)  # a dip under what was found by < REFINE_STEP / 2 may stay
            floor = min(self.limit, best) - 0.5 * REFINE_STEP
            if span < REFINE_STEP or 0.5 * (da + db - span) >= floor:
                continue
            m = 0.5 * (a + b)
            dm = self._measure(start + m * step)
            if dm < best:
                best, best_s = dm, m
            parts += [(a, m, da, dm), (m, b, dm, db)]
        return best, best_s

    def describe(self, x: FloatArray) -> str:
        """What comes closest at the coordinates ``x``, how close, and the limit (for a check
        a motion started under, where it started)."""
        d = self._measure(np.asarray(x, dtype=float))
        g = self.interference
        c = int(g.best[0])
        slack = float(g.slack[c])
        floor = self._floor(c)
        mm = float(g.distance[c]) * 1e3
        # as many decimals as tell the distance from its floor ("3.612 mm, closer than the
        # 3.613 mm", not "... than the 3.61 mm"), two at least, four (0.1 µm) at most; within
        # a µm of it, "at" it
        digits = next((k for k in (2, 3) if distance_words(mm / 1e3, k)
                       != distance_words(floor, k)), 4)  # fmt: skip
        under = "at" if floor * 1e3 - mm < 1e-3 else "under"
        what = f"{g.name(c)}: {distance_words(mm / 1e3, digits)}"
        if not d < self.limit:
            return what
        if slack > 0.0:
            since = "at the home pose" if self._home_floor[c] else "the motion started at"
            return (f"{what}, closer than {since} ({distance_words(floor, digits)}), {under} "
                    f"the clearance {self.limit * 1e3:.2f} mm")  # fmt: skip
        return f"{what}, {under} the clearance {self.limit * 1e3:.2f} mm"

    def pair_at(self, x: FloatArray) -> str:
        """What comes closest at the coordinates ``x``, in words (what against what)."""
        self._measure(np.asarray(x, dtype=float))
        return self.interference.name(int(self.interference.best[0]))

    def closest_at(self, x: FloatArray) -> tuple[float, str]:
        """At the coordinates ``x``: the distance (m, as measured: not lifted by a slack) of
        the pair closest to its limit and that pair in words, with where its motion started
        when it started under the clearance."""
        self._measure(np.asarray(x, dtype=float))
        g = self.interference
        c = int(g.best[0])
        since = "at the home pose it goes to" if self._home_floor[c] else "since the start"
        started = (f", under the clearance {since} ({distance_words(self._floor(c))} there: no "
                   "closer allowed)" if g.slack[c] > 0.0 else "")  # fmt: skip
        return float(g.distance[c]), f"{g.name(c)}{started}"

    def _floor(self, c: int) -> float:
        """m: the least distance check ``c`` may come to: where its motion started, for one
        that started under the clearance (``relax_from``), else the clearance."""
        slack = float(self.interference.slack[c])
        return self.limit - slack + START_TOLERANCE if slack > 0.0 else self.limit
