"""What moves the reference besides ``move``: a jog and a path are motion sources — planned
outside the loop against the soft limits, stepped in the loop before the supervisor looks at
the trajectory, writing their progress into ``ControlData``. The trajectory they feed and the
soft limits they plan against are given in each call (no source keeps them). Which one may
take over from which is one rule, the desk's (``CommandDesk._take_motion``)."""

from __future__ import annotations

from cdprctl.control.data import ControlData
from cdprctl.model.robot import RobotModel
from cdprctl.motion.trajectory import Trajectory


class MotionSource:
    def __init__(self, model: RobotModel, data: ControlData):
        self.model = model
        self.data = data

    def update(self, t: float, trajectory: Trajectory) -> None:
        """In the cycle, before the supervisor looks at the trajectory."""
        raise NotImplementedError
