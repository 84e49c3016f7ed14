"""Contacts in the simulated robot (issue 67): the same least distances the controller
measures (``cdprctl/geometry/interference.py``: cable against cable, the platform's body, the cell),
here at the plant's true pose after each step, and every contact recorded — so that a test
or a run shows whether the controller stopped the robot before one happened.

A contact is a distance of 0 or less (two cables touching or crossing, a cable into the body
or an obstacle, the platform's body into an obstacle: negative, how deep), counted for each
pair as it begins (a pair that touches while another already does is a contact of its own:
a newcomer's cable went through a beam unsaid while the body sat in a crate). Measured
once per ``CdprPlant.step`` (a control period): at the top speed of a
shipped robot (1 m/s) and 4 ms a step the platform moves 4 mm between two measurements, so
a grazing touch shorter than that can pass unseen; the least distance met (``least``) says
how near it came.
"""

from __future__ import annotations

import math

import numpy as np

from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.interference import Interference
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.model.robot import RobotModel

#: the exit code of ``cdprctl run --sim`` and ``cdprctl sim`` whose simulated robot recorded a
#: contact where they would have exited 0 (4 is ``daemon.startup.NOT_CALIBRATED``)
CONTACT_EXIT = 5
#: m: a contact ends when its pair is this far apart again
RELEASE = 1e-6


class ContactRecorder:
    def __init__(self, model: RobotModel):
        self.model = model
        self.interference = Interference(model)
        self.active = len(self.interference.distance) > 0
        self._kin = KinematicsData(model)
        self.least = math.inf  # m: the least distance met so far
        self.least_what = ""  # which pair, and when (s of simulated time)
        self.contacts: list[tuple[float, str]] = []  # (s, what): each contact's start
        self._pairs: dict[str, None] = {}  # the pairs that touched, in order (their names)
        n = len(self.interference.distance)
        self._touching = np.zeros(n, dtype=bool)  # per check: touching at the last step
        self._now = np.zeros(n, dtype=bool)
        self._new = np.zeros(n, dtype=bool)
        if self.active:  # the kernels loaded here, not in the first real-time step
            inverse_kinematics(model, self._kin, model.home.position, model.home.rotation)
            self.interference.update(self._kin)

    def update(self, t: float, position: FloatArray, rotation: FloatArray) -> None:
        """The distances at the true pose ``position`` (m, P in the base frame), ``rotation``
        (platform → base) at time ``t`` (s)."""
        if not self.active:
            return
        inverse_kinematics(self.model, self._kin, position, rotation)
        g = self.interference
        g.update(self._kin)
        d = g.minimum
        if d < self.least:
            self.least, self.least_what = d, f"{g.describe()} at t = {t:.3f} s"
        if d > RELEASE and not self._touching.any():
            return  # nothing touches, nothing did: the usual step, no work
        # touching at 0 or under; a touch ends above RELEASE (a face resting on a face
        # flickers about 0 by rounding: one contact, not one a flicker)
        np.less_equal(g.distance, 0.0, out=self._now)
        np.greater(self._now, self._touching, out=self._new)  # began this step
        if self._new.any():
            for c in np.flatnonzero(self._new):
                self.contacts.append((t, g.describe(int(c))))
                self._pairs[g.name(int(c))] = None
        np.less_equal(g.distance, RELEASE, out=self._new)
        np.logical_and(self._touching, self._new, out=self._touching)
        np.logical_or(self._touching, self._now, out=self._touching)

    def report(self) -> str:
        """One line: the contacts, or none and how near the cables came."""
        if not self.active:
            return "nothing to check for contacts (one cable)"
        if not self.contacts:
            return f"no contact; the closest: {self.least_what}"
        t, what = self.contacts[0]
        deepest = f"; the deepest: {self.least_what}" if self.least < 0.0 else ""
        pairs = list(self._pairs)
        others = (f"; {len(pairs)} pairs: {', '.join(pairs[:6])}{', ...' if len(pairs) > 6 else ''}"
                  if len(pairs) > 1 else "")  # fmt: skip
        return (f"{len(self.contacts)} contact(s), the first at t = {t:.3f} s (the simulated "
                f"robot's clock): {what}{deepest}{others}")
