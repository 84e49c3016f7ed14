"""The cables' clearance every cycle (issue 67): the least distance between two cables, a
cable and the platform's body, a cable and the cell, the body and the cell at the estimated pose
(``cdprctl/geometry/interference.py``, into ``ControlData.interference``), and the supervisor's
check of it (``FaultKind.CLEARANCE``).

The rule: the robot stops when the distance is under the clearance (``[interference]
clearance``) by more than ``NOISE``, or under it at all for ``HOLD``. The soft limits keep
every target, move, path and jog at the clearance (``motion/limits.py``), so only the platform
leaving its reference brings a cable closer: a disturbance, a tracking error, or the
estimate's own noise. The distance is 1-Lipschitz in the cables' points, which move with the
estimated pose: the estimate's noise at rest (encoder counts through the forward kinematics,
the stretch refreshed at 50 Hz) is µm, at most tens of µm in a badly conditioned direction
(docs/control.md), far under ``NOISE`` = 0.5 mm; a dip of 0.5 mm, a tenth of the default
clearance, still leaves 4.5 mm to contact. ``HOLD`` (10 ms, a few cycles) rides through
a one-cycle spike of the estimate (a stale or re-stretched sample) but not a platform that
stays too close.

A robot enabled under the clearance (its geometry, or after such a stop) may move out of
it: the soft limits then allow no closer than where the motion started (a straight motion
home: than home), and this check takes, for each check under the clearance at the first
supervised cycle or at the home pose, the lower of its two distances less ``NOISE`` as that
check's limit (``relax_kernel``: the other checks keep the whole clearance — a platform
resting on the floor does not switch off its cables' checks; a robot enabled away from home
may still be moved home), until the state leaves the supervised ones
(``StateMachine.forget_when_unsupervised``).
"""

from __future__ import annotations

import math

import numpy as np

from cdprctl.control.supervision.persistence import Persistence
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.interference import Interference, distance_words, relax_kernel


class ClearanceWatch:
    #: m: how far under the limit the distance may dip for up to ``HOLD`` (estimate noise)
    NOISE = 0.0005
    #: s: how long it may stay under the limit by less than ``NOISE``
    HOLD = 0.01

    def __init__(self, interference: Interference, home: FloatArray | None = None):
        """``home``: m per check, the distances at the home pose (``Clearance.home_distance``;
        None: not known, no such floor)."""
        self.interference = interference
        self.clearance = interference.clearance  # m
        self.active = len(interference.distance) > 0
        n = len(interference.distance)
        self.home = np.full(n, math.inf) if home is None else np.array(home, dtype=float)  # own
        self._home_least = float(self.home.min()) if n else math.inf
        self._floor = np.zeros(n)  # m per check: the first cycle's or home's, the lower
        self.limit = math.nan  # m: this supervised run's (NaN: not set yet)
        self._under = Persistence(self.HOLD)

    def held(self, t: float, on: bool, weight: float = 1.0) -> bool:
        """Forgotten when the state leaves the supervised ones (``on`` False): the next
        supervised run takes its limit anew."""
        if not on:
            self.limit = math.nan
            self.interference.slack.fill(0.0)
            self._under.held(t, False)
        return False

    def check(self, t: float) -> str | None:
        """Why the last measured distance stops the robot, or None."""
        if not self.active:
            return None
        g = self.interference
        if self.limit != self.limit:  # the first supervised cycle
            d = min(g.minimum, self._home_least)
            self.limit = self.clearance if d >= self.clearance else d - self.NOISE
            if d < self.clearance:  # those checks no closer than here or home, less NOISE
                np.minimum(g.distance, self.home, out=self._floor)
                relax_kernel(self._floor, g.slack, self.clearance + self.NOISE, self.clearance)
        e = g.effective  # m: against the clearance
        deep = e < self.clearance - self.NOISE
        if not (self._under.held(t, e < self.clearance) or deep):
            return None
        how = (f"by more than {self.NOISE * 1e3:.1f} mm" if deep else
               f"for {self.HOLD * 1e3:.0f} ms")  # fmt: skip
        limit = self.clearance - g.slack.item(g.best.item(0))  # m: this check's
        under = (f"under the limit {limit * 1e3:.2f} mm" if limit >= 0.0 else
                 f"deeper than its limit ({distance_words(limit)})")  # fmt: skip
        return (f"clearance: {g.describe()}, {under} ([interference] clearance "
                f"{self.clearance * 1e3:.2f} mm) {how}")  # fmt: skip
