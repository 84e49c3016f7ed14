"""The ``[safety]`` section: the holding brakes' test (docs/safety.md, "Brake test")."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cdprctl.model.reader import TableReader

SAFETY_KEYS = (
    "brake_test_interval",
    "brake_test_torque_factor",
    "brake_test_torque",
    "brake_test_max_counts",
    "brake_test_hold",
)


@dataclass(frozen=True)
class SafetyConfig:
    # s: a real robot's last passed brake test may be this old when it is enabled (8 h, the
    # common periodic test; `cdprctl run` refuses past it)
    brake_test_interval: float = 8 * 3600.0
    # the test torque as a multiple of the torque the cable's worst-case load (its tension
    # limit) puts on its brake (1.3: the margin brake tests commonly apply)
    brake_test_torque_factor: float = 1.3
    # N·m at the motor: a fixed test torque instead (None: from the factor); never above a
    # drive's torque limit (capped, and said)
    brake_test_torque: float | None = None
    # encoder counts a brake may let its motor turn under the test torque and pass
    brake_test_max_counts: int = 4
    # s the test torque is held at its full value (after a 0.5 s ramp)
    brake_test_hold: float = 1.0


def read_safety(rd: TableReader, data: dict[str, Any]) -> SafetyConfig:
    t = rd.table(data, "safety", "", required=False)
    if t is None:
        return SafetyConfig()
    rd.check_keys(t, SAFETY_KEYS, "safety")
    d = SafetyConfig()
    interval = rd.number(t, "brake_test_interval", "safety", "s", required=False,
                         default=d.brake_test_interval, minimum=60.0)  # fmt: skip
    factor = rd.number(t, "brake_test_torque_factor", "safety", "", required=False,
                       default=d.brake_test_torque_factor, minimum=1.0, maximum=3.0)  # fmt: skip
    torque = rd.number(t, "brake_test_torque", "safety", "N·m", required=False, positive=True)
    counts = rd.number(t, "brake_test_max_counts", "safety", "counts", required=False,
                       default=d.brake_test_max_counts, minimum=1, integer=True)  # fmt: skip
    hold = rd.number(t, "brake_test_hold", "safety", "s", required=False,
                     default=d.brake_test_hold, minimum=0.1, maximum=10.0)  # fmt: skip
    if interval is None or factor is None or counts is None or hold is None:
        return d  # the errors are in ``rd``
    return SafetyConfig(interval, factor, torque, int(counts), hold)
