"""The words the drives and the control side share: the driver's lifecycle (ros2_control's
hardware-interface states), a drive's protocol-independent state, the winches' feedback (SI at
the motor shaft, preallocated and overwritten by ``WinchDriver.read``) and the driver's
counters. Plain definitions: no protocol, no bus."""

from __future__ import annotations

import enum
import math

import numpy as np


class Lifecycle(enum.Enum):
    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"  # buses open, feedback readable, drives not enabled
    ACTIVE = "active"  # drives enabled, torque commands applied
    ERROR = "error"
    FINALIZED = "finalized"


# Each lifecycle state bound to a name once: on Python 3.11 reading ``Lifecycle.X`` goes
# through ``EnumType.__getattr__``, which builds a method wrapper per read (3.12 dropped
# it): the control cycle reads these (tests/test_allocations.py).
UNCONFIGURED, INACTIVE, ACTIVE = Lifecycle.UNCONFIGURED, Lifecycle.INACTIVE, Lifecycle.ACTIVE
ERROR, FINALIZED = Lifecycle.ERROR, Lifecycle.FINALIZED


class DriveState(enum.IntEnum):
    """Protocol-independent drive state."""

    UNKNOWN = 0  # no feedback yet
    DISABLED = 1  # power stage off (brake holds)
    READY = 2  # ready / switched on, not enabled
    ENABLED = 3  # torque applied
    QUICK_STOP = 4
    FAULT = 5


class WinchStates:
    """Feedback of every winch (SI, motor side), preallocated and overwritten by ``read``."""

    def __init__(self, m: int):
        self.position = np.zeros(m)  # rad
        self.velocity = np.zeros(m)  # rad/s
        self.torque = np.zeros(m)  # N·m
        self.state = np.zeros(m, dtype=np.int64)  # DriveState
        self.feedback_age = np.full(m, math.inf)  # s since the last feedback
        self.sampled_at = np.full(m, -math.inf)  # s: when the last feedback was taken (its SYNC)
        self.fault_code = np.zeros(m, dtype=np.int64)  # drive error code, 0 when none
        # N: each cable's load cell's tension (NaN: no cell, or none heard within its
        # timeout) and s since its last value (drivers/load_cells.py)
        self.tension = np.full(m, math.nan)
        self.tension_age = np.full(m, math.inf)
        self.stamp = 0.0  # s, the time given to read()


class DriverStats:
    def __init__(self) -> None:
        self.cycles = 0
        self.frames_sent = 0
        self.frames_received = 0
        self.frames_ignored = 0  # foreign ids, wrong lengths
        self.missed_feedback = 0  # cable-cycles without feedback
        self.implausible_frames = 0  # position steps no motor can make: dropped
        self.clamped_commands = 0  # torques beyond the limit, clamped
        self.rejected_commands = 0  # non-finite torques, replaced by the last valid one
        self.send_errors = 0  # frames the bus would not take (link down, bus-off, TX full)
        self.receive_errors = 0  # reads the bus refused (link down)

    def as_dict(self) -> dict[str, int]:
        return dict(vars(self))
