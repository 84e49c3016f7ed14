"""Payloads on Zenoh: versioned JSON (``application/json``), documented in docs/telemetry.md.

Keys under the robot's prefix ``P`` (``cdpr/<robot>`` by default):

* ``P/state``  — at ``zenoh.state_rate``: pose, twist, reference, target, tracking error,
  tensions, torques, motor positions, TDA method and status, supervisor state, fault.
* ``P/timing`` — at ``zenoh.timing_rate``: the loop's statistics.
* ``P/events`` — reliable: state changes, faults, command outcomes, as they happen.
* ``P/status`` — a queryable: state, fault, config summary, versions.
* ``P/cmd/<kind>`` — commands (puts); the answer comes on ``P/reply/<kind>``.
"""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from cdprctl.control.data import MOTIONS, PATH_STATES
from cdprctl.control.states import ACTIVE_STATES
from cdprctl.geometry.gripper_mechanics import GraspState
from cdprctl.telemetry.snapshot import FAULT_KINDS, STATES, TDA_METHODS, TDA_STATUSES, TIMING

GRASP_STATES = [s.value for s in GraspState]

SCHEMA = "cdprctl/1"  # bumped on any incompatible change; additions keep the version


def _float(x: float, digits: int = 6) -> float | None:
    return round(float(x), digits) if math.isfinite(x) else None


def _floats(a: np.ndarray, digits: int = 6) -> list[float | None]:
    return [_float(x, digits) for x in a]


def pose_payload(snap: dict[str, np.ndarray]) -> dict[str, Any]:
    return {"position": _floats(snap["position"]), "rpy": _floats(snap["rpy"])}


def _fault_kind(snap: dict[str, np.ndarray]) -> str:
    """The supervisor's FaultKind of the current fault ("" when none)."""
    i = float(snap["fault_kind"][0])
    return FAULT_KINDS[int(i)] if math.isfinite(i) and 0 <= i < len(FAULT_KINDS) else ""


#: the states whose drives are enabled: their brakes released
POWERED = frozenset(s.value for s in ACTIVE_STATES)


def safety_payload(snap: dict[str, np.ndarray], brake_test: Any = None) -> dict[str, Any]:
    """The safety state (docs/safety.md): the safety chain as the drives report it (open: they
    report safe torque off, the e-stop state), the brakes as the drives' state implies them,
    the stop category under way or the last one's, the check that tripped, and the brake
    test on record (``brake_test``: the daemon's, fixed for the run)."""
    state = STATES[int(snap["state"][0])]
    cat = float(snap["stop_category"][0])
    return {
        "chain": "open" if state == "estop" else "closed",
        "brakes": "released" if state in POWERED else "closed",
        "stop_category": int(cat) if math.isfinite(cat) and cat >= 0 else None,
        "tripped": _fault_kind(snap),
        "brake_test": brake_test,
    }


def state_payload(
    snap: dict[str, np.ndarray],
    cable_names: list[str],
    fault: str,
    gripper_names: list[str] | tuple[str, ...] = (),
    brake_test: Any = None,
    parts: tuple[list[str], list[str]] = ([], []),
) -> dict[str, Any]:
    """``parts``: the names of the platform's body parts and of the cell's obstacles (the
    clearance's pair)."""
    true = snap["true_position"]
    grip = [
        {
            "cable": name,
            "state": GRASP_STATES[int(snap["grip_state"][j])]
            if math.isfinite(snap["grip_state"][j])
            else None,
            "travel": _float(snap["grip_travel"][j], 5),  # m
            "force": _float(snap["grip_force"][j], 3),  # N
            "energy": _float(snap["grip_energy"][j], 4),  # J
            "target": _float(snap["grip_target"][j], 5),  # m
        }
        for j, name in enumerate(gripper_names)
    ]
    return {
        "schema": SCHEMA,
        "time": round(float(snap["time"][0]), 6),
        "cycle": int(snap["cycle"][0]),
        "state": STATES[int(snap["state"][0])],
        "fault": fault,
        "fault_kind": _fault_kind(snap),
        "safety": safety_payload(snap, brake_test),
        "pose": pose_payload(snap),
        "twist": {"velocity": _floats(snap["velocity"]), "omega": _floats(snap["omega"])},
        "reference": _floats(snap["reference"]),
        "target": _floats(snap["target"]),
        "tracking_error": _floats(snap["error"]),
        "external_wrench_estimate": _floats(snap["external_wrench"], 3),
        "cables": cable_names,
        "tensions": _floats(snap["tensions"], 3),
        "torques": _floats(snap["torques"], 5),
        "motor_position": _floats(snap["motor_position"]),
        "motor_target": _floats(snap["motor_target"]),
        "measured_tensions": _floats(snap["measured_tensions"], 3),
        **_motion(snap),
        "tda": {
            "method": TDA_METHODS[int(snap["tda_method"][0])],
            "status": TDA_STATUSES[int(snap["tda_status"][0])],
            "saturation": _float(snap["saturation"][0], 4),
            "saturated_cycles": int(snap["saturated_cycles"][0])
            if math.isfinite(snap["saturated_cycles"][0])
            else 0,
        },
        **({"true_position": _floats(true)} if np.all(np.isfinite(true)) else {}),
        **({"grippers": grip} if grip else {}),
        "clearance": clearance_payload(snap["clearance"], cable_names, parts),
    }


#: ``Interference.checks[:, 0]`` in words (``geometry/interference.py``: CABLE, BODY, OBSTACLE,
#: PLATFORM: the platform's body against an obstacle)
CHECK_KINDS = ("cable", "body", "obstacle", "platform")


def clearance_parts(model: Any) -> tuple[list[str], list[str]]:
    """The names of ``model``'s body parts and obstacles, for ``state_payload``'s ``parts``."""
    cfg = model.interference
    return [b.name for b in cfg.body], [o.name for o in cfg.obstacles]


def clearance_payload(
    c: np.ndarray, cables: list[str], parts: tuple[list[str], list[str]]
) -> dict[str, Any] | None:
    """The least distance at the estimate (m), what it is between (the cable, then the other
    cable, body part or obstacle; or the body's part, then the obstacle), the closest points
    on each (m, base frame) and the clearance (m); None with nothing to check."""
    if not np.all(np.isfinite(c[1:4])):
        return None
    kind, i, k = int(c[1]), int(c[2]), int(c[3])
    if kind == 0:
        first, other = cables[i], cables[k]
    elif kind == 3:  # the body's part i against obstacle k
        first, other = _part(parts[0], i, "body"), _part(parts[1], k, "obstacle")
    else:
        first, other = cables[i], _part(parts[kind - 1], k, CHECK_KINDS[kind])
    return {
        "distance": _float(c[0]),
        "kind": CHECK_KINDS[kind],
        "between": [first, other],
        "points": [_floats(c[4:7]), _floats(c[7:10])],
        "limit": _float(c[10]),
    }


def _part(names: list[str], k: int, kind: str) -> str:
    return names[k] if k < len(names) else f"{kind} {k + 1}"


def _motion(snap: dict[str, np.ndarray]) -> dict[str, Any]:
    """What moves the reference, and a path's progress (segment 1-based, fraction of it, s
    played and s left as planned)."""
    m, p = snap["motion"][0], snap["path"]
    if not (math.isfinite(m) and np.all(np.isfinite(p))):
        return {"motion": "", "path": None}
    path = None
    if p[1] > 0:
        path = {"segment": int(p[0]), "segments": int(p[1]), "fraction": round(float(p[2]), 4),
                "state": PATH_STATES[int(p[3])], "elapsed": round(float(p[4]), 3),
                "time_left": round(float(p[5]), 3)}  # fmt: skip
    return {"motion": MOTIONS[int(m)], "path": path}


def timing_payload(snap: dict[str, np.ndarray]) -> dict[str, Any]:
    t = snap["timing"]
    return {
        "schema": SCHEMA,
        "time": round(float(snap["time"][0]), 6),
        **{k: (float(v) if math.isfinite(v) else None) for k, v in zip(TIMING, t, strict=True)},
    }


def event_payload(t: float, text: str, kind: str = "event") -> dict[str, Any]:
    return {"schema": SCHEMA, "time": round(t, 6), "kind": kind, "text": text}


def encode(payload: dict[str, Any]) -> bytes:
    return json.dumps(payload, separators=(",", ":"), allow_nan=False).encode()
