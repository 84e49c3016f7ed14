"""The tensions that hold the platform still under gravity at a pose: what a simulated robot
parked there carries, and what a calibration holds it with (docs/homing.md)."""

from __future__ import annotations

from cdprctl.gripper import GripperSet
from cdprctl.kinematics import KinematicsData
from cdprctl.model.robot import RobotModel
from cdprctl.rotation import FloatArray
from cdprctl.tda.solver import TensionDistributor
from cdprctl.tda.types import TDAMethod, TDAOptions


def equilibrium_tensions(model: RobotModel, kin: KinematicsData) -> FloatArray:
    """Tensions (N) holding the platform's weight (and the jaws', eq. (46)) at the pose of
    ``kin``: the barycenter (QP for r != 2; the minimum energy when the robot's TDA is the
    energy one); the minimum tensions when the pose cannot be held."""
    method = TDAMethod.BARYCENTER if model.redundancy == 2 else TDAMethod.QP
    if model.control.tda_method == "energy":  # the robot was parked by its own distribution
        method = TDAMethod.ENERGY
    gs = GripperSet(model)
    R = kin.rotation
    load = gs.parallel_load(R)
    hold = -(model.gravity_wrench(R) + gs.weight_wrench(R))
    out = TensionDistributor(model, TDAOptions(method=method)).solve(
        kin.W, gs.spring_wrench(kin.W, hold, load), k=model.cable_stiffness(kin.length)
    )
    t = out.tensions.copy() if out.ok else model.tension_min.copy()
    t[gs.cables] += load  # jB carries the jaws
    return t
