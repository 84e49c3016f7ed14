"""Everything one control cycle produces, in one place: the arrays (allocated once, rewritten
in place every cycle) and the scalars outside readers see — the daemon's status line, the
telemetry snapshot, the recordings and the tests read this, never a component's internals.

Pose and trajectory arrays are the estimator's and the trajectory's own (references, no
copies); the rest is written by the component named beside it.
"""

from __future__ import annotations

import collections
import math
from typing import Any

import numpy as np

from cdprctl.control.states import FaultKind, State
from cdprctl.tda import TDAStatus

PHASES = ("read", "estimate", "trajectory", "control", "tda", "torques", "write")
MOTIONS = ("", "move", "jog", "path")  # what moves the reference ("": holding)
PATH_STATES = ("", "running", "dwell", "paused", "done", "aborted", "stopped")


class ControlData:
    def __init__(self, m: int, g: int):
        """``m`` cables, ``g`` grippers; each stage's outputs allocated once here."""
        self._supervision()
        self._pose_control()
        self._cable_outputs(m)
        self._gripper_outputs(g)
        self._bound(m)
        self._motion()

    def _supervision(self) -> None:
        """The state, its faults and stops, the loop's clock and its logs."""
        self.state = State.INIT
        self.fault_reason = ""
        self.fault_kind: FaultKind | None = None
        # the stop under way or the last one's (IEC 60204-1 category 0, 1, 2; -1: none since
        # the last enable or reset): docs/safety.md
        self.stop_category = -1
        # cycles run (``cycle``), counted in place by the controller (numerics.count_kernel)
        self.cycles = np.zeros(1, dtype=np.int64)
        self.time = 0.0  # s, the loop's clock at the last cycle
        # s, the real time since the cycle before (a period, or more after a late or missed
        # one): every time-dependent part steps by it (controller.py)
        self.dt = 0.0
        # (t, text) for the daemon's log and the telemetry; drained outside the loop
        self.events: collections.deque[tuple[float, str]] = collections.deque(maxlen=256)
        # (t, kind) of every fault, for counting by kind (the daemon's summary, the soak)
        self.faults: collections.deque[tuple[float, FaultKind]] = collections.deque(maxlen=256)

    def _pose_control(self) -> None:
        """The pose controller's outputs: the error, the wrench asked for, its saturation."""
        self.pose_error = np.zeros(6)  # m, rad: desired − estimated
        self.wrench = np.zeros(6)  # N, N·m: what the cables were asked for
        self.feedback_wrench = np.zeros(6)  # N, N·m: the PID's part of it (wrench.py)
        # the fraction of the feedback the cables could give this cycle (1: all; see
        # distribution.py), the time (s) it was below 1 (leaking while it is not:
        # Controller.SATURATION_LEAK), and the cycles it was
        self.saturation = 1.0
        self.saturated_for = 0.0
        self.saturated_cycles = 0
        self.ext_total = np.zeros(6)  # N, N·m: the known external wrench, jaws' weight included
        self.ext_estimate = np.zeros(6)  # N, N·m at P, base frame: the observer's (observer.py)

    def _cable_outputs(self, m: int) -> None:
        """Per cable (``m``): the tension distribution's and the winch torques' outputs."""
        # tension distribution (distribution.py)
        self.tensions = np.zeros(m)  # N, commanded
        self.hold_tensions = np.zeros(m)  # N, the last feasible distribution
        self.stretch_tensions = np.zeros(m)  # N, feed-forward ones, for the estimator
        # N: what the drives' torques say the cables carry, low-passed (cable_space.py; in
        # position mode the estimator's stretch tensions while the drives are on)
        self.measured_tensions = np.zeros(m)
        # N: measured − commanded tensions, both through that low-pass (the supervisor's
        # check of the cables in position mode)
        self.tension_error = np.zeros(m)
        # N: its internal part (the null space of W: no external wrench explains it)
        self.internal_tension_error = np.zeros(m)
        # diag(N Nᵀ): how much of a cable's own tension error shows in that part (0..1)
        self.internal_leverage = np.ones(m)
        self.tda_status = TDAStatus.OK
        # winch torques (torques.py)
        self.torques = np.zeros(m)  # N·m, motor, commanded (the feed-forward in position mode)
        self.motor_target = np.zeros(m)  # rad: each winch's position target (cable_space.py)

    def _gripper_outputs(self, g: int) -> None:
        """Per gripper (``g``, gripper_control.py), and each phase's time of the last cycle."""
        self.jb_load = np.zeros(g)  # N, what each jB carries
        self.grip_target = np.full(g, math.nan)  # m, commanded travel
        self.grip_imposed = np.full(g, math.nan)  # m, ramping towards it
        # µs per phase of the last cycle (PHASES; the manager's read/write, the rest the
        # controller's)
        self.phase_us = np.zeros(len(PHASES))

    def _bound(self, m: int) -> None:
        """What the controller binds or sets once: the estimator's and trajectory's arrays,
        the grasp sensor, the clearance, the TDA method and the gains."""
        # references, bound by the controller: estimator and trajectory arrays, the grasp
        # sensor, the TDA options in use, the drives' motor angles
        self.position: np.ndarray = np.zeros(3)  # m, P in the base frame
        self.rotation: np.ndarray = np.eye(3)
        self.velocity: np.ndarray = np.zeros(3)  # m/s
        self.omega: np.ndarray = np.zeros(3)  # rad/s, base frame
        self.reference: np.ndarray = np.zeros(6)  # trajectory now (m, rotation vector rad)
        self.target: np.ndarray = np.zeros(6)  # where the trajectory ends
        self.motor_position: np.ndarray = np.zeros(m)  # rad
        self.grasp: Any = None  # GraspSensor, with grippers
        # the cables' clearance at the estimated pose: ``Interference`` (its ``distance`` m,
        # ``best``, ``closest`` m, base frame), written every cycle (controller.py)
        self.interference: Any = None
        self.tda_method = ""
        # where the loop's gains come from, set once (controller.py): force_feedback rad/s,
        # disturbance_bandwidth Hz, pose_bandwidth Hz per axis (torque mode's, set by hand)
        self.gains: dict[str, Any] = {}

    def _motion(self) -> None:
        """What moves the reference, and a path's progress (path_follower.py)."""
        self.motion = ""
        self.path_state = ""  # PATH_STATES
        self.path_segment = 0  # 1-based, 0: no path
        self.path_segments = 0
        self.path_fraction = 0.0  # of the segment's distance covered
        self.path_elapsed = 0.0  # s the path has moved (or dwelt), pauses not counted
        self.path_time_left = 0.0  # s of the plan still to play (as planned)

    @property
    def cycle(self) -> int:
        """Cycles run (an int built per read: readers are outside the loop)."""
        return int(self.cycles[0])
