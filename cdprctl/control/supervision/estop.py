"""The emergency stop as the controller sees it: the drives' safety chain open (safe torque off
at their STO inputs, ``drivers.errors.SafeTorqueOffError``; docs/safety.md). Not a fault of the
robot's: the drives have no torque and their brakes hold whatever cdprctl does. What is left
to it: enter the e-stop state once (no FAULT, no re-enable), measure the platform's drop onto
the brakes until it is at rest, and say so. Plain arithmetic on preallocated arrays."""

from __future__ import annotations

import math

import numpy as np

from cdprctl.control.supervision.persistence import Persistence
from drivers.errors import DriveFaultError, DriverError, SafeTorqueOffError


class EmergencyStop:
    AT_REST = 0.005  # m/s: the estimated speed under which the platform is at rest
    REST_FOR = 0.2  # s at rest before the drop is final
    # s after a reset from the e-stop in which a drive still in fault refused it (the
    # driver's recovery settles in 0.5 s)
    REFUSAL_WITHIN = 2.0

    def __init__(self) -> None:
        self.since = math.nan  # s: when the chain was seen open
        self.start = np.zeros(3)  # m, base frame: the estimated position then
        self.drop = np.zeros(3)  # m: where it went from there (at rest: final)
        self.settled = True
        self.reset_at = -math.inf  # s: the last reset from the e-stop
        self._rest = Persistence(self.REST_FOR)

    def refused(self, t: float, err: DriverError | None) -> bool:
        """Whether ``err`` at ``t`` is the drives refusing a reset from the e-stop: a drive
        still in fault within ``REFUSAL_WITHIN`` s of it (they take none while the chain is
        open, and say no code again: the driver cleared the one they sent)."""
        return isinstance(err, DriveFaultError) and t - self.reset_at < self.REFUSAL_WITHIN

    def enter(self, t: float, position: np.ndarray, err: DriveFaultError) -> str:
        """The event of the e-stop's start at ``t`` (s), ``position`` (m) the estimate."""
        self.since = t
        self.start[:] = position
        self.drop[:] = 0.0
        self.settled = False
        self._rest.held(t, False)
        who = f"the drive of cable index {err.cable} (node {err.node_id})"
        if not isinstance(err, SafeTorqueOffError):  # a refused reset
            self.reset_at = -math.inf
            return (f"EMERGENCY STOP: the safety chain is still open: {who} stayed in fault "
                    "after the reset; reset once the chain is closed")  # fmt: skip
        return (
            f"EMERGENCY STOP: the safety chain is open: {who} reports {err.description} "
            f"(0x{err.code:04X}); no torque, the brakes close; reset once the chain is closed"
        )

    def watch(self, t: float, position: np.ndarray, speed: float) -> str | None:
        """Each cycle in the e-stop: the drop so far; once the platform has been at rest for
        ``REST_FOR`` s, the event saying how far it went and how long it took."""
        if self.settled:
            return None
        np.subtract(position, self.start, out=self.drop)
        if not self._rest.held(t, speed < self.AT_REST):
            return None
        self.settled = True
        rest_since = t - self._rest.dose
        d = np.round(self.drop * 1e3, 1) + 0.0  # + 0.0 after rounding: no "-0.0" in the text
        return (
            f"emergency stop: on the brakes, the platform {math.hypot(*d.tolist()):.1f} mm from "
            f"where the chain opened ([{d[0]:+.1f}, {d[1]:+.1f}, {d[2]:+.1f}] mm, as the drums "
            f"moved: the cables' stretch and swing come on top), at rest "
            f"{rest_since - self.since:.2f} s after"
        )
