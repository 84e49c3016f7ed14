"""The reconfigurable end-effector in the loop (Sensors 2019 §2.4): the jaws' weight wrench
joins the known external wrench (eq. (46)), the TDA's impositions hold or drive each jaw's
travel, the grasp is sensed from the drives, and gripper commands are checked against what the
redundancy can give here."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cdprctl.control.command_types import GripKind, GripperCommand
from cdprctl.control.cycle.distribution import Distribution
from cdprctl.control.cycle.estimator import Estimator
from cdprctl.control.cycle.grasp import GraspSensor
from cdprctl.control.cycle.reference_pose import WorkingPose
from cdprctl.control.cycle.torques import WinchTorques, friction_kernel
from cdprctl.control.data import ControlData
from cdprctl.geometry.gripper_mechanics import GraspState, GripperSet
from cdprctl.model.robot import RobotModel
from cdprctl.motion.trajectory import Trajectory
from cdprctl.tda import ImposedQuantity, Imposition, TDAMethod, TDAOptions, TensionDistributor
from cdprctl.tda.grip_range import travel_range
from drivers.vocabulary import WinchStates


class GripperControl:
    # The imposed travel moves at this speed: a jump of the imposition is a jump of two cables'
    # tensions, which the jaw and the platform would feel as a blow.
    GRIP_SPEED = 0.02  # m/s

    def __init__(
        self,
        model: RobotModel,
        data: ControlData,
        grippers: GripperSet,
        estimator: Estimator,
        at: WorkingPose,
        winches: WinchTorques,
        distribution: Distribution,
        ext_wrench: np.ndarray,
        trajectory: Trajectory,
    ):
        self.model = model
        self.trajectory = trajectory  # its acceleration: the jaws' inertia
        self.data = data
        self.set = grippers
        self.estimator = estimator  # the grasp is sensed at the estimated pose
        self.at = at  # the jaws' loads and the range at the working pose (reference_pose.py)
        self.winches = winches
        self.distribution = distribution
        self.ext_wrench = ext_wrench  # N, N·m: the known external wrench without the jaws
        self.period = model.control.period
        self.grasp = GraspSensor(grippers, self.period)
        data.grasp = self.grasp
        n, c = grippers.n, grippers.cables
        # scratch for the sensing, per gripper
        self._friction = np.zeros(n)
        self._torque = np.zeros(n)
        self._delta = np.zeros(n)
        self._cables = np.asarray(c, dtype=np.int64)
        self._jaw_wrench = np.zeros(6)  # N, N·m: the jaws' weight and inertia
        # the options this set last imposed, and the impositions of other cables they kept
        self._imposed: TDAOptions | None = None
        self._keep: tuple[Imposition, ...] = ()
        # the range check's scratch distributor (grip_range replaces its options)
        self._range_tda = (
            TensionDistributor(
                model, TDAOptions(method=TDAMethod.ENERGY, period=model.control.period)
            )
            if n
            else None
        )

    @property
    def n(self) -> int:
        return self.set.n

    def update(self, st: WinchStates | None, sense: bool) -> None:
        """The jaws' weight wrench and jB's load at the working pose's orientation (in
        position mode the reference's, ``reference_pose.py``); the grasp state
        from the drives' torque and position (``sense``); the imposed travels ramped."""
        gs, e, d = self.set, self.estimator, self.data
        R = self.at.rotation
        # the jaws' weight and inertia at the trajectory's acceleration: 20 kg swinging on
        # seed000's springs unfed moved the platform 6.4 mm in its demo (position mode; torque
        # mode's pose loop held it to 5.2), fed forward 1.8 (lock-step, 250 Hz)
        tr = self.trajectory
        gs.jaw_loads(R, tr.acceleration, tr.velocity, self._jaw_wrench, d.jb_load)
        np.add(self.ext_wrench, self._jaw_wrench, out=d.ext_total)
        if sense and st is not None:
            c, w = self._cables, self.winches
            friction_kernel(w.terms, st.velocity, c, self._friction)
            r = w.r[c]
            l0 = e.l_zero[c] - r * st.position[c]
            self._torque[:] = st.torque[c] - self._friction
            self._delta[:] = e.kin.length[c] - l0
            self.grasp.update(self._torque / r, self._delta, d.jb_load)
        # jB's load as the open model has it: the sensed squeeze is not fed back here (a loop
        # through the sensor's own estimate drifted into an infeasible wrench in lock-step);
        # a squeeze command puts the force into the imposition instead (command())
        self._ramp()

    def warm_up(self) -> None:
        """Compile the sensing's and the jaws' kernels on scratch arrays (``warm_up.py``)."""
        w = self.winches
        friction_kernel(w.terms, np.zeros(len(w.r)), self._cables, self._friction)
        tr = self.trajectory
        self.set.jaw_loads(
            self.at.rotation, tr.acceleration, tr.velocity, self._jaw_wrench,
            np.zeros(self.set.n),
        )  # fmt: skip

    def travel_range(self, j: int) -> tuple[float, float]:
        """Travel (m) the redundancy can give gripper ``j`` here, the other grippers held
        where they are imposed (``grip_range.travel_range``). NaN when none."""
        e, dist = self.at, self.distribution
        if self._range_tda is None:  # no grippers
            return math.nan, math.nan
        return travel_range(
            self.model,
            self._range_tda,
            self.set,
            j,
            self.data.grip_imposed,
            e.kin.W,
            e.rotation,
            e.k,
            self.ext_wrench,
            dist.t_min,
            dist.t_max,
        )

    def command(self, t: float, cmd: GripperCommand) -> None:
        gs, j, d = self.set, cmd.gripper, self.data
        if not 0 <= j < gs.n:
            d.events.append((t, f"gripper {j} refused: the robot has {gs.n} gripper(s)"))
            return
        name = self.model.grippers[j].name
        lo, hi = self.travel_range(j)
        if cmd.grip is GripKind.TRAVEL:
            target = cmd.value
        elif cmd.grip is GripKind.FORCE:
            if self.grasp.state[j] is GraspState.OPEN:
                d.events.append(
                    (t, f"gripper {name} squeeze refused: no contact sensed (close it first)")
                )
                return
            # eq. (43): F_BA = K_B (δ − L21), the object taken as rigid; the cable carries
            # F_BA on top of K_A δ (eq. (26)), so the imposed spring travel holds F_BA/K_A more
            target = float(self.grasp.contact_travel[j]) + cmd.value * (
                1.0 / float(gs.k_b[j]) + 1.0 / float(gs.k_a[j])
            )
        else:  # release: as open as the redundancy allows here
            target = lo + 0.002 if math.isfinite(lo) else math.nan
        if not (math.isfinite(target) and lo <= target <= hi):
            d.events.append(
                (
                    t,
                    f"gripper {name} {cmd.grip.value} refused: travel {target * 1e3:.1f} mm is "
                    f"outside what the redundancy gives here, [{lo * 1e3:.1f}, {hi * 1e3:.1f}] mm",
                )
            )
            return
        d.grip_target[j] = target
        d.events.append((t, f"gripper {name} {cmd.grip.value}: travel to {target * 1e3:.1f} mm"))

    def hold(self) -> None:
        """Every gripper holds the travel it has: left to the minimum of energy, a jaw would
        wander with every change of the wrench, and its 10 kg on K_A (a ~1.6 Hz mode) fed the
        platform's loop a growing oscillation near the end of the other gripper's range
        (lock-step, seed000_grippers)."""
        gs, d = self.set, self.data
        if not gs.n:
            return
        travel = (d.hold_tensions[gs.cables] - d.jb_load) / gs.k_a
        for j in range(gs.n):
            if math.isnan(d.grip_target[j]):
                d.grip_target[j] = d.grip_imposed[j] = float(travel[j])
        self._apply()

    def _ramp(self) -> None:
        d = self.data
        step = self.GRIP_SPEED * (d.dt if d.dt > 0.0 else self.period)
        changed = False
        for j in range(self.set.n):
            target = d.grip_target[j]
            if math.isnan(target):
                continue
            cur = d.grip_imposed[j]
            if math.isnan(cur):
                cur = float(self.grasp.travel[j])
            new = cur + max(-step, min(step, target - cur))
            if new != d.grip_imposed[j]:
                d.grip_imposed[j] = new
                changed = True
        if changed:
            self._apply()

    def _apply(self) -> None:
        gs, d = self.set, self.data
        base = self.distribution.options
        if base is not self._imposed:  # options from elsewhere: their other impositions
            self._keep = tuple(i for i in base.impositions if i.cable not in gs.cables)
        keep = self._keep
        # the moving ones last: at the end of its range the TDA saturates the last imposition
        # (the one being driven there), not a gripper that holds
        holding = [j for j in range(gs.n) if d.grip_imposed[j] == d.grip_target[j]]
        moving = [j for j in range(gs.n) if d.grip_imposed[j] != d.grip_target[j]]
        grip = tuple(
            Imposition(int(gs.cables[j]), ImposedQuantity.DEFORMATION, float(d.grip_imposed[j]))
            for j in holding + moving
            if not math.isnan(d.grip_imposed[j])
        )
        self.distribution.impose(keep + grip)
        self._imposed = self.distribution.options

    def status(self) -> list[dict[str, Any]]:
        g, d = self.grasp, self.data
        force, energy = g.reported_force(), g.energies()
        return [
            {
                "cable": x.name,
                "state": g.state[j].value,
                "travel": float(g.travel[j]),
                "force": float(force[j]),
                "contact_travel": float(g.contact_travel[j]),
                "energy": float(energy[j]),
                "tension": float(g.tension[j]),
                "target": float(d.grip_target[j]),
            }
            for j, x in enumerate(self.model.grippers)
        ]
