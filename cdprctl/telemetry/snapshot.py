"""The loop's state in shared memory, written by the daemon's I/O thread and read by the
gateway process (a sequence lock: the writer makes the counter odd while it writes, so a
reader retries instead of taking a torn copy). No pickling, no lock the loop could wait on.
"""

from __future__ import annotations

from multiprocessing import shared_memory
from typing import Any

import numpy as np

from cdprctl.control.data import MOTIONS, PATH_STATES, ControlData
from cdprctl.control.states import FaultKind, State
from cdprctl.tda import TDAMethod, TDAStatus

STATES = [s.value for s in State]
FAULT_KINDS = [k.value for k in FaultKind]
TDA_METHODS = [m.value for m in TDAMethod]
TDA_STATUSES = [s.name for s in TDAStatus]
TIMING = (
    "cycles",
    "lateness_p50_us",
    "lateness_p99_us",
    "lateness_max_us",
    "compute_p50_us",
    "compute_p99_us",
    "overruns",
    "missed",
    "missed_percent",
)


class Layout:
    """Slices of the shared float64 vector for a robot of ``m`` cables."""

    def __init__(self, m: int, g: int = 0):
        fields = [
            ("seq", 1),
            ("time", 1),  # s, the loop's monotonic clock
            ("state", 1),
            ("fault_kind", 1),  # index in FAULT_KINDS, −1: none
            ("stop_category", 1),  # IEC 60204-1's, the stop under way or the last; −1: none
            ("tda_method", 1),
            ("tda_status", 1),
            ("saturation", 1),  # the fraction of the feedback wrench the cables give (1: all)
            ("saturated_cycles", 1),
            ("cycle", 1),
            ("motion", 1),  # index in MOTIONS
            # segment (1-based), segments, fraction of the segment, PATH_STATES index, s played
            # (pauses not counted), s left as planned
            ("path", 6),
            ("position", 3),  # m, P in the base frame
            ("rpy", 3),  # rad, roll-pitch-yaw of the platform in the base frame
            ("velocity", 3),  # m/s
            ("omega", 3),  # rad/s, base frame
            ("reference", 6),  # m and rad (rotation vector from home): the trajectory now
            ("target", 6),  # same, where the trajectory ends
            ("error", 6),  # m and rad: reference − estimate
            ("external_wrench", 6),  # N, N·m at P, base frame: the observer's estimate
            ("tensions", m),  # N, commanded
            ("torques", m),  # N·m, motor, commanded
            ("motor_position", m),  # rad
            ("motor_target", m),  # rad, position mode's targets (the motors' own otherwise)
            ("measured_tensions", m),  # N, from the drives' torques (position mode)
            ("true_position", 3),  # m, the simulated plant's (NaN on a real robot)
            # the cables' least distance at the estimate (cdprctl/geometry/interference.py): m, the
            # check's kind (0 cable, 1 body, 2 obstacle), cable (0-based), the other (cable,
            # body part, obstacle; 0-based), the closest points on each (m, base frame), and
            # the clearance (m); NaN: nothing to check
            ("clearance", 11),
            ("timing", len(TIMING)),
            # the reconfigurable end-effector, per gripper (docs/gripper.md)
            ("grip_state", g),  # index in GRASP_STATES
            ("grip_travel", g),  # m, δ from the drives
            ("grip_force", g),  # N, estimated squeeze
            ("grip_energy", g),  # J, actuator energy, eq. (36)/(40)
            ("grip_target", g),  # m, commanded travel
        ]
        self.slices: dict[str, slice] = {}
        i = 0
        for name, n in fields:
            self.slices[name] = slice(i, i + n)
            i += n
        self.size = i


class SharedSnapshot:
    """Create (``name=None``, the daemon) or attach to (the gateway) the shared block."""

    def __init__(self, m: int, name: str | None = None, g: int = 0):
        self.layout = Layout(m, g)
        nbytes = self.layout.size * 8
        self._owner = name is None
        self.shm = shared_memory.SharedMemory(name=name, create=self._owner, size=nbytes)
        self.buf: np.ndarray = np.ndarray(
            (self.layout.size,), dtype=np.float64, buffer=self.shm.buf
        )
        if self._owner:
            self.buf[:] = np.nan
            self.buf[0] = 0.0
        self._copy = np.empty_like(self.buf)

    @property
    def name(self) -> str:
        return self.shm.name

    def write(self, values: dict[str, Any]) -> None:
        """Write the fields given (arrays or numbers), one sequence step."""
        b, sl = self.buf, self.layout.slices
        b[0] += 1.0  # odd: writing
        for key, v in values.items():
            b[sl[key]] = v
        b[0] += 1.0  # even: consistent

    def read(self, tries: int = 100) -> dict[str, np.ndarray] | None:
        """A consistent copy as named arrays, None if never written or always torn."""
        b, c = self.buf, self._copy
        for _ in range(tries):
            s1 = b[0]
            c[:] = b
            if s1 == b[0] and s1 % 2 == 0:
                if s1 == 0:
                    return None
                return {k: c[s].copy() for k, s in self.layout.slices.items()}
        return None

    def close(self) -> None:
        del self.buf
        self.shm.close()
        if self._owner:
            self.shm.unlink()


def controller_values(d: ControlData, true_position: Any = None) -> dict[str, Any]:
    """The snapshot fields from the loop's ``ControlData`` (called by the I/O thread)."""
    from cdprctl.core.rotation import matrix_to_rpy

    out: dict[str, Any] = {
        "time": d.time,
        "state": STATES.index(d.state.value),
        "fault_kind": FAULT_KINDS.index(d.fault_kind.value) if d.fault_kind is not None else -1,
        "stop_category": d.stop_category,
        "tda_method": TDA_METHODS.index(d.tda_method),
        "tda_status": TDA_STATUSES.index(d.tda_status.name),
        "saturation": d.saturation,
        "saturated_cycles": d.saturated_cycles,
        "cycle": d.cycle,
        "motion": MOTIONS.index(d.motion),
        "path": (d.path_segment, d.path_segments, d.path_fraction,
                 PATH_STATES.index(d.path_state), d.path_elapsed, d.path_time_left),
        "position": d.position,
        "rpy": matrix_to_rpy(d.rotation),
        "velocity": d.velocity,
        "omega": d.omega,
        "reference": d.reference,
        "target": d.target,
        "error": d.pose_error,
        "external_wrench": d.ext_estimate,
        "tensions": d.tensions,
        "torques": d.torques,
        "motor_position": d.motor_position,
        "motor_target": d.motor_target,
        "measured_tensions": d.measured_tensions,
    }
    if true_position is not None:
        out["true_position"] = true_position
    g = d.interference
    if g is not None and len(g.distance):
        c = int(g.best[0])
        out["clearance"] = (g.distance[c], *g.checks[c, :3], *g.closest[c], g.clearance)
    if d.grasp is not None and len(d.grip_target):
        from cdprctl.geometry.gripper_mechanics import GraspState

        states = list(GraspState)
        g = d.grasp
        out["grip_state"] = [states.index(s) for s in g.state]
        out["grip_travel"] = g.travel
        out["grip_force"] = g.reported_force()
        out["grip_energy"] = g.energies()
        out["grip_target"] = d.grip_target
    return out


def timing_values(stats: Any, last: int | None = None) -> np.ndarray:
    """The ``TIMING`` fields; percentiles over the ``last`` cycles (all when None)."""
    s = stats.summary(last)
    return np.array([float(s.get(k, 0.0)) for k in TIMING])
