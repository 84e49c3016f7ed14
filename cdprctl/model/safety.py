"""The ``[safety]`` section: the holding brakes' test and which stop category each fault takes
(docs/safety.md, "Brake test", "Stop categories")."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from cdprctl.model.reader import TableReader

SAFETY_KEYS = (
    "brake_test_interval",
    "brake_test_torque_factor",
    "brake_test_torque",
    "brake_test_max_counts",
    "brake_test_hold",
    "stop_category",
)

WRONG_MODEL = "a slipped or broken cable: holding powered on a wrong model is no state to stay in"
#: per fault kind (``control.states.FaultKind``'s values): the stop categories it may take
#: (``[safety.stop_category]``), the first its default, and why the others are not offered
STOP_CATEGORIES: dict[str, tuple[tuple[int, ...], str]] = {
    "drive fault": ((0,), "the drive itself has stopped producing torque: its brake holds"),
    "drive silent": ((0,), "a drive that does not answer cannot be asked to hold"),
    "drives": ((0,), "the driver cannot operate the drives"),
    "enable timeout": ((0,), "the drives never took the platform"),
    "beyond capacity": ((0,), "the motors cannot hold the load; the brakes hold more"),
    "during the stop": ((0,), "the controlled stop itself failed"),
    "forward kinematics": ((1, 0), "without a pose there is no pose to keep holding"),
    "encoders disagree": ((1, 0), WRONG_MODEL),
    "cable tension": ((1, 0), WRONG_MODEL),
    "feedback age": ((1, 0), "holding powered on old feedback is no state to stay in"),
    "internal error": ((1, 0), "the cycle failed once; it is not to be trusted for longer"),
    "tracking": ((1, 0, 2), ""),
    "orientation": ((1, 0, 2), ""),
    "platform speed": ((1, 0, 2), ""),
    "tension distribution": ((1, 0, 2), ""),
    "clearance": ((1, 0, 2), ""),
    "load cell": ((1, 0, 2), ""),
}


def stop_key(kind: str) -> str:
    """A fault kind as a key of ``[safety.stop_category]`` ("drive fault" → drive_fault)."""
    return kind.replace(" ", "_")


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
    # fault kind (``FaultKind`` value) → stop category; the kinds absent take their default
    stop_category: dict[str, int] = field(default_factory=dict)

    def category_of(self, kind: str) -> int:
        """The stop category a fault of ``kind`` takes."""
        return self.stop_category.get(kind, STOP_CATEGORIES[kind][0][0])


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
    stops = _read_stops(rd, t)
    if interval is None or factor is None or counts is None or hold is None:
        return d  # the errors are in ``rd``
    return SafetyConfig(interval, factor, torque, int(counts), hold, stops)


def _read_stops(rd: TableReader, t: dict[str, Any]) -> dict[str, int]:
    """``[safety.stop_category]``: ``kind = category`` for the fault kinds given."""
    table = rd.table(t, "stop_category", "safety", required=False)
    if table is None:
        return {}
    kinds = {stop_key(k): k for k in STOP_CATEGORIES}
    rd.check_keys(table, kinds, "safety.stop_category")
    out: dict[str, int] = {}
    for key, value in table.items():
        if key not in kinds:
            continue
        allowed, why = STOP_CATEGORIES[kinds[key]]
        if not isinstance(value, int) or isinstance(value, bool) or value not in allowed:
            only = ", ".join(map(str, sorted(allowed)))
            rule = f"must be an integer, one of {only}" + (f" ({why})" if why else "")
            rule += f" (written {value!r}: a float)" if isinstance(value, float) else ""
            rd.error(f"safety.stop_category.{key}", value, "", rule)
            continue
        out[kinds[key]] = int(value)
    return out
