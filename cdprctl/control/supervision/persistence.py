"""How long a condition has held, for the checks that fault only on what persists (the
supervisor's, ``states.PERSISTENCE``) and the e-stop's rest. Plain arithmetic."""

from __future__ import annotations

import math


class Persistence:
    """How long a condition has held: ``held(t, on)`` is True once it has been on for
    ``duration`` s without a break (the persistent faults of ``states.PERSISTENCE``).
    ``weight`` (≥ 1) counts each interval that many times: the further beyond its limit, the
    sooner (the inverse-time characteristic of protection relays); 1 is plain time."""

    def __init__(self, duration: float):
        self.duration = duration  # s
        self.dose = 0.0  # s, weighted time on
        self.last = math.inf  # s, the last sample while on

    def held(self, t: float, on: bool, weight: float = 1.0) -> bool:
        if not on:
            self.dose, self.last = 0.0, math.inf
            return False
        if t > self.last:
            self.dose += weight * (t - self.last)
        self.last = t
        return self.dose >= self.duration - 1e-9
