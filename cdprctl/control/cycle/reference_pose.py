"""The pose the loop works at: the feed-forward wrench (gravity's moment, the platform's
inertia), the tension distribution, the jaws' loads and the winches' torque feed-forward are
computed there. Torque mode: the estimate (``Estimator``), which the pose loop closes on.
Position mode (``ReferencePose``): the trajectory's reference, moved by the estimate's
deviation from it through a first-order low-pass a decade below the drives' position loops
(``[drives] position_loop_bandwidth`` / 10: 5 Hz as shipped), stepped once a cycle.

Why not the estimate itself in position mode: there the commanded tensions set the targets
through the cables' stretch (``cable_space.motor_target_kernel``) — on the Sensors 2019
springs (1000 N/m, r/G = 5 mm/rad) 0.2 rad of motor per newton. Computed at the pose the
encoders give, they closed a loop through the drives' own loops and a period's delay that
nobody designed: after a stall drives 3 and 5 of seed000 with its grippers rang in
opposition, their rates changing sign every cycle, until one stopped on its following error
(lock-step, stalls of 2-30 ms in 2 % of the cycles: 8 faults in 8 runs at 500 Hz, 2 in 4 at
250 Hz). A decade below the inner loops is the usual separation of a cascade's outer one:
with it none of those runs faulted (the worst drive at 0.50 of its window), where at twice
the cut-off a stall pattern through a reversal still took one to 0.79.
Why not the reference alone: what persists of a deviation is real — a platform pushed off by
a load beyond the cables, a snapped or slipping cable — and the tensions for where it is hold
it better: at the reference the controlled stop after a snapped cable let rowc go 45.8 mm
(36.4 at the estimate, 38.6 through the low-pass), after a slipping winch 11.1 mm (8.0, 8.6).
Stepped once a cycle, not by a late cycle's length: after a stall the estimate's deviation is
the drives' own carry-on, which ``CableSpace._after_stall`` takes back; stepped by the stall
the pose took much of it at once: two stall patterns took a drive to 0.34 / 0.63 of its window
(0.22 / 0.34 stepped once a cycle; at 10 Hz, 1.25: a fault) (docs/control.md, "The working
pose")."""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np
from numba import njit

from cdprctl.control.cycle.cycle_io import ReferenceArgs, pose_args
from cdprctl.core.numerics import compliance_of, cycle_kernel, kernel_args, stiffness_kernel
from cdprctl.core.rotation import FloatArray, log_relative_kernel, rotated_kernel
from cdprctl.geometry.kinematics import KinematicsData, ik_kernel
from cdprctl.model.robot import RobotModel

# the working pose's low-pass, below the drives' position loops by this factor (a decade)
BELOW_DRIVE_LOOPS = 10.0


class WorkingPose(Protocol):
    """What the loop reads of the pose it works at: ``Estimator`` (torque mode) or
    ``ReferencePose`` (position mode)."""

    position: FloatArray  # m, base frame
    rotation: FloatArray  # platform → base
    velocity: FloatArray  # m/s, base frame
    omega: FloatArray  # rad/s, base frame
    kin: KinematicsData  # the inverse kinematics there: W, lengths
    k: FloatArray  # N/m, each cable's stiffness there


@cycle_kernel
def reference_pose_kernel(
    ref, R_home, est_p, est_R, alpha, offset, law, ref_kin, kin, pose, k, work
):  # pragma: no cover - compiled  # fmt: skip
    """The reference ``x`` (m, rotation vector rad from ``R_home``; rate ``xd``: ``ref``, a
    ``Reference``) with its
    inverse kinematics into ``ref_kin``, ``R_ref`` = exp(x[3:]) R_home; ``offset`` (m, rad,
    base frame) ← a low-pass step ``offset + alpha (dev − offset)`` towards the estimate's
    (``est_p``, ``est_R``) deviation from it, ``dev`` = [est_p − x, log(est_R R_refᵀ)]; the
    working pose (``pose``, a ``PoseEstimate``) ``p`` = x + offset[:3], ``R`` = exp(offset[3:])
    R_ref with its inverse kinematics into ``kin`` and each cable's stiffness ``k`` (N/m) at
    its length; ``v`` (m/s), ``w`` (rad/s: the rotation vector's rate, the angular velocity to
    first order, as the trajectory's acceleration is taken) the reference's. ``work``:
    ``R_ref``, ``E`` (3, 3) scratch, ``dev`` (6,)."""
    x, xd = ref[0], ref[1]
    p, R, v, w = pose
    R_ref, E, dev = work
    rotated_kernel(x[3:], R_home, E, R_ref)
    for i in range(3):
        v[i] = xd[i]
        w[i] = xd[3 + i]
        dev[i] = est_p[i] - x[i]
    ik_kernel(ref_kin, x[:3], R_ref)
    log_relative_kernel(est_R, R_ref, E, dev[3:])
    for i in range(6):
        offset[i] += alpha * (dev[i] - offset[i])
    for i in range(3):
        p[i] = x[i] + offset[i]
    rotated_kernel(offset[3:], R_ref, E, R)
    ik_kernel(kin, p, R)
    stiffness_kernel(kin[9], law, k)  # KinArrays.length


@njit(cache=True)
def pose_at_rest_kernel(p, R, law, ref_kin, kin, k):  # pragma: no cover - compiled
    """The inverse kinematics into ``ref_kin`` and ``kin``, the stiffness ``k`` (N/m), at
    ``p`` (m), ``R``."""
    ik_kernel(ref_kin, p, R)
    ik_kernel(kin, p, R)
    stiffness_kernel(kin[9], law, k)  # KinArrays.length


class ReferencePose:
    """Position mode's working pose, with what the loop reads of a pose (``WorkingPose``:
    ``position``, ``rotation``, ``velocity``, ``omega``, ``kin``, ``k``, written in place),
    and the inverse kinematics at the reference itself, ``reference_kin``: the targets'
    lengths (``CableSpace``), which the encoders do not reach at all."""

    def __init__(self, model: RobotModel):
        self.position = np.array(model.home.position, dtype=float)
        self.rotation = np.array(model.home.rotation, dtype=float)
        self.velocity = np.zeros(3)
        self.omega = np.zeros(3)
        self.kin = KinematicsData(model)
        self.k = np.zeros(model.n_cables)
        self.reference_kin = KinematicsData(model)
        # Hz: the low-pass from the estimate's deviation to the working pose, stepped once a
        # cycle (the module's docstring says why not by a late cycle's length)
        self.bandwidth = model.drives.position_loop_bandwidth / BELOW_DRIVE_LOOPS
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * self.bandwidth * model.control.period)
        self.offset = np.zeros(6)  # m, rad (base frame): the deviation low-passed
        self._R_home = np.ascontiguousarray(model.home.rotation, dtype=float)
        # the cable law, as the kernels take it (its own: the estimator's terms, computed alike)
        self._law = kernel_args(compliance_of(model.cables))
        # the kernel's bundles: this working pose, a scratch
        self._pose = pose_args(self)
        self._work = (np.zeros((3, 3)), np.zeros((3, 3)), np.zeros(6))  # R_ref, E, dev
        self.hold(self.position, self.rotation)

    def update(self, reference: ReferenceArgs, estimate: WorkingPose) -> None:
        """At the trajectory's ``reference`` now, moved by the ``estimate``'s deviation from
        it through the low-pass, one period's step (each cycle, after the trajectory's)."""
        reference_pose_kernel(
            reference, self._R_home, estimate.position, estimate.rotation, self._alpha,
            self.offset, self._law, self.reference_kin.arrays, self.kin.arrays, self._pose,
            self.k, self._work,
        )  # fmt: skip

    def hold(self, position: FloatArray, rotation: FloatArray) -> None:
        """At ``position`` (m), ``rotation``, at rest, no deviation: before there is a
        reference (start-up, where the estimate is all there is)."""
        self.position[:] = position
        self.rotation[:] = rotation
        self.velocity[:] = 0.0
        self.omega[:] = 0.0
        self.offset[:] = 0.0
        pose_at_rest_kernel(
            self.position, self.rotation, self._law, self.reference_kin.arrays,
            self.kin.arrays, self.k,
        )  # fmt: skip

    def restart(self) -> None:
        """No deviation carried (enabling: the reference starts at the estimate)."""
        self.offset[:] = 0.0
