"""The cycle's bundles: what each stage of ``Controller.update`` reads and writes, named.

Each bundle is the kernels' plain tuple (``numerics.kernel_args``) of a ``NamedTuple`` of
``pd_kernel.py`` over arrays one stage writes in place: built once, by the controller, and
handed to the stages that read it in each call — no stage keeps another's arrays (issue 66;
``tests/control/cycle/test_no_shared_arrays.py`` holds it). The stages and the bundles between them:

::

    feedback (WinchStates, the manager's read)
      → Estimator.update        → estimate   (p, R, v, w: PoseEstimate; W and k in its kin)
      → Trajectory.update       → reference  (x, ẋ, ẍ: Reference)
      → ReferencePose.update    → working    (position mode; torque mode: the estimate)
      → PoseController.update   → wrench     (pose error, wrench, its feedback part: Wrench)
      → Distribution.distribute → tensions   (ControlData.tensions)
      → WinchTorques.update     → torques    (ControlData.torques)
      → CableSpace.targets      → targets    (ControlData.motor_target, position mode)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple, Protocol, cast

import numpy as np

from cdprctl.control.cycle.pd_kernel import PoseEstimate, Reference
from cdprctl.control.data import ControlData
from cdprctl.core.numerics import kernel_args
from cdprctl.core.rotation import FloatArray

#: a ``Reference``'s arrays as the kernels take them: x (6,), ẋ (6,), ẍ (6,)
ReferenceArgs = tuple[np.ndarray, np.ndarray, np.ndarray]
#: a ``PoseEstimate``'s arrays as the kernels take them: p (3,), R (3, 3), v (3,), ω (3,)
PoseArgs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
#: a ``Wrench``'s arrays as the kernels take them
WrenchArgs = tuple[np.ndarray, np.ndarray, np.ndarray]


class Wrench(NamedTuple):
    """The pose controller's output: the pose error (m, rad: desired − working pose), the
    wrench the cables are asked for (N, N·m at P, base frame), and its feedback part."""

    pose_error: np.ndarray
    wrench: np.ndarray
    feedback: np.ndarray


class PoseArrays(Protocol):
    """What a pose stage writes in place (``Estimator``, ``ReferencePose``)."""

    position: FloatArray
    rotation: FloatArray
    velocity: FloatArray
    omega: FloatArray


def reference_args(position: np.ndarray, velocity: np.ndarray,
                   acceleration: np.ndarray) -> ReferenceArgs:  # fmt: skip
    """A trajectory's reference (its ``position``, ``velocity``, ``acceleration``) as a
    bundle."""
    return cast(ReferenceArgs, kernel_args(Reference(position, velocity, acceleration)))


def pose_args(pose: PoseArrays) -> PoseArgs:
    """A pose stage's arrays as a bundle."""
    p = PoseEstimate(pose.position, pose.rotation, pose.velocity, pose.omega)
    return cast(PoseArgs, kernel_args(p))


@dataclass(frozen=True)
class CycleIO:
    """The bundles of one controller, built once (``build``)."""

    reference: ReferenceArgs  # the trajectory's, written by Trajectory.update
    estimate: PoseArgs  # the estimator's, written by Estimator.update
    working: PoseArgs  # the pose the loop works at (reference_pose.py)
    wrench: WrenchArgs  # ControlData's, written by PoseController.update

    @staticmethod
    def build(reference: ReferenceArgs, estimate: PoseArrays, working: PoseArrays,
              data: ControlData) -> CycleIO:  # fmt: skip
        w = Wrench(data.pose_error, data.wrench, data.feedback_wrench)
        wrench = cast(WrenchArgs, kernel_args(w))
        return CycleIO(reference, pose_args(estimate), pose_args(working), wrench)
