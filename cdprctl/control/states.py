"""The supervisor's states and the kinds of fault: plain definitions, shared by the control
layer, the telemetry and the tools (no logic here; ``supervisor.py`` has the transitions)."""

from __future__ import annotations

import enum


class State(enum.Enum):
    INIT = "init"
    READY = "ready"  # drives inactive (brakes), feedback live, pose estimated
    ENABLING = "enabling"
    ENABLED = "enabled"  # holding the pose
    MOVING = "moving"
    DISABLING = "disabling"
    STOPPING = "stopping"  # a fault: holding, then disabling
    FAULT = "fault"
    ESTOP = "estop"  # the drives' safety chain open (safe torque off): not a fault; estop.py


# Each state bound to a name once: on Python 3.11 reading ``State.X`` goes
# through ``EnumType.__getattr__``, which builds a method wrapper per read (3.12 dropped
# it): the control cycle reads these (tests/control/cycle/test_allocations.py).
INIT, READY, ENABLING, ENABLED, MOVING = (
    State.INIT, State.READY, State.ENABLING, State.ENABLED, State.MOVING
)  # fmt: skip
DISABLING, STOPPING, FAULT, ESTOP = State.DISABLING, State.STOPPING, State.FAULT, State.ESTOP

# The sets of states are tuples: ``in`` finds a member by identity, where a frozenset hashed
# it by Enum's Python ``__hash__`` and built an int each time.
#: the states in which the controller commands tensions (DISABLING: decelerating to rest)
ACTIVE_STATES = (ENABLING, ENABLED, MOVING, DISABLING, STOPPING)
#: the states in which the pose loop integrates and a TDA switch is blended (the supervisor
#: also watches DISABLING and STOPPING)
HEALTHY_STATES = (ENABLED, MOVING)


class FaultKind(enum.StrEnum):
    """Why the supervisor stopped the robot. ``PERSISTENCE`` says for each kind whether one
    cycle suffices and why, or what must persist first."""

    DRIVE_FAULT = "drive fault"
    DRIVE_SILENT = "drive silent"
    DRIVES = "drives"
    ENABLE_TIMEOUT = "enable timeout"
    FORWARD_KINEMATICS = "forward kinematics"
    ENCODERS_DISAGREE = "encoders disagree"
    TRACKING = "tracking"
    ORIENTATION = "orientation"
    OVER_SPEED = "platform speed"
    FEEDBACK_AGE = "feedback age"
    TENSION_DISTRIBUTION = "tension distribution"
    CABLE_TENSION = "cable tension"
    BEYOND_CAPACITY = "beyond capacity"
    CLEARANCE = "clearance"
    DURING_STOP = "during the stop"
    INTERNAL = "internal error"
    LOAD_CELL = "load cell"


PERSISTENCE: dict[FaultKind, str] = {
    FaultKind.DRIVE_FAULT: "immediate: the drive itself reports a fault and has stopped "
    "producing torque (in position mode also its following error: 3 ms beyond the error at "
    "which its loop asks for the full torque — an encoder that jumped, a load beyond the winch)",
    FaultKind.DRIVE_SILENT: "persistent: the driver's own time limits (heartbeat, feedback) "
    "have run out",
    FaultKind.DRIVES: "immediate: the driver cannot operate the drives",
    FaultKind.ENABLE_TIMEOUT: "persistent: the drives did not reach operation within 2 s",
    FaultKind.FORWARD_KINEMATICS: "immediate: without a pose no tension can be computed",
    FaultKind.ENCODERS_DISAGREE: "immediate: a residual beyond any elastic stretch is an encoder "
    "jump, a slipped or a broken cable",
    FaultKind.TRACKING: "immediate: the error bound is the hazard itself",
    FaultKind.ORIENTATION: "immediate: the error bound is the hazard itself",
    FaultKind.OVER_SPEED: "persistent: 30 ms over the limit (taking over from the brakes gives "
    "short false spikes)",
    FaultKind.FEEDBACK_AGE: "persistent: the limit is itself a time ([control] max_feedback_age), "
    "at two reads in a row (a stall of the loop itself leaves one read with old feedback)",
    FaultKind.TENSION_DISTRIBUTION: "persistent: the feedback wrench saturated longer than "
    "[control.safety] max_saturation_time (the cables give what they can meanwhile), or 3 "
    "cycles in which even the feed-forward cannot be held (the last feasible tensions held)",
    FaultKind.CABLE_TENSION: "persistent: inverse-time, 50 ms at the limit, less the further "
    "beyond it (position mode): the measured tensions pull against each other in a way no "
    "external wrench explains — a cable longer or shorter than its encoder says (a slipped or "
    "a broken cable); the measurement is low-passed at 20 Hz and a move's transients pass "
    "through it",
    FaultKind.BEYOND_CAPACITY: "persistent: 30 ms of a drive at its torque limit while the "
    "drives hold the lengths (position mode): the cables cannot hold the platform, a stop on "
    "the motors would be dragged; the brakes, which hold more than the motors, close at once",
    FaultKind.CLEARANCE: "persistent: 10 ms under the clearance, or at once 0.5 mm under it "
    "(the estimate's noise is µm; clearance_watch.py): two cables, a cable and the platform's "
    "body or the cell closer than [interference] clearance",
    FaultKind.DURING_STOP: "immediate: the drives failed while the controlled stop held the pose",
    FaultKind.INTERNAL: "immediate: the cycle itself failed",
    FaultKind.LOAD_CELL: "persistent: a cell silent beyond its own timeout ([[sensors."
    "load_cells]] timeout, 30 ms), or the cell and its drive's torque apart beyond both their "
    "errors for [sensors] disagreement_time (50 ms), both low-passed at 20 Hz: a cell's noise "
    "and a lost frame ride through (control/cycle/tension_source.py)",
}
