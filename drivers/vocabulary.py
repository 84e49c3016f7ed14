"""The words the drives and the control side share: the driver's lifecycle (ros2_control's
hardware-interface states), a drive's protocol-independent state, the winches' feedback (SI at
the motor shaft, preallocated and overwritten by ``WinchDriver.read``) and the driver's
counters. Plain definitions: no protocol, no bus."""

from __future__ import annotations

import enum
import math

import numpy as np

from cdprctl.core.numerics import add_count


class Lifecycle(enum.Enum):
    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"  # buses open, feedback readable, drives not enabled
    ACTIVE = "active"  # drives enabled, torque commands applied
    ERROR = "error"
    FINALIZED = "finalized"


# Each lifecycle state bound to a name once: on Python 3.11 reading ``Lifecycle.X`` goes
# through ``EnumType.__getattr__``, which builds a method wrapper per read (3.12 dropped
# it): the control cycle reads these (tests/control/cycle/test_allocations.py).
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


#: The driver's counters, in the order of ``DriverStats.counts``
STAT_NAMES = (
    "cycles",
    "frames_sent",
    "frames_received",
    "frames_ignored",  # foreign ids, wrong lengths
    "missed_feedback",  # cable-cycles without feedback
    "implausible_frames",  # position steps no motor can make: dropped
    "clamped_commands",  # torques beyond the limit, clamped
    "rejected_commands",  # non-finite torques, replaced by the last valid one
    "send_errors",  # frames the bus would not take (link down, bus-off, TX full)
    "receive_errors",  # reads the bus refused (link down)
)
CYCLES, FRAMES_SENT, FRAMES_RECEIVED, FRAMES_IGNORED = 0, 1, 2, 3
MISSED_FEEDBACK, IMPLAUSIBLE_FRAMES, CLAMPED_COMMANDS, REJECTED_COMMANDS = 4, 5, 6, 7


class _Count:
    """One of ``DriverStats.counts`` as an int attribute (a read builds the int: readers are
    outside the loop; the loop adds in place, ``numerics.add_count``)."""

    def __init__(self, slot: int):
        self.slot = slot

    def __get__(self, stats: DriverStats, owner: object = None) -> int:
        return int(stats.counts[self.slot])

    def __set__(self, stats: DriverStats, value: int) -> None:
        stats.counts[self.slot] = value


class DriverStats:
    """The driver's counters (``STAT_NAMES``), kept in an int64 array: a Python int past 256
    took a block at every increment of the loop's."""

    cycles = _Count(0)
    frames_sent = _Count(1)
    frames_received = _Count(2)
    frames_ignored = _Count(3)
    missed_feedback = _Count(4)
    implausible_frames = _Count(5)
    clamped_commands = _Count(6)
    rejected_commands = _Count(7)
    send_errors = _Count(8)
    receive_errors = _Count(9)

    def __init__(self) -> None:
        self.counts = np.zeros(len(STAT_NAMES), dtype=np.int64)

    def cycle(self) -> None:
        """One write more (in place)."""
        add_count(self.counts, CYCLES, 1)

    def commands(self, rejected: int, clamped: int) -> None:
        """A write's torques replaced (non-finite) and clamped, counted in place."""
        add_count(self.counts, REJECTED_COMMANDS, rejected)
        add_count(self.counts, CLAMPED_COMMANDS, clamped)

    def as_dict(self) -> dict[str, int]:
        return {name: int(self.counts[i]) for i, name in enumerate(STAT_NAMES)}
