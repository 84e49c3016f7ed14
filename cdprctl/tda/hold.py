"""The tensions that hold the platform still under gravity at a pose: what a simulated robot
parked there carries, and what a calibration holds it with (docs/homing.md)."""

from __future__ import annotations

import dataclasses

from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.gripper_mechanics import GripperSet
from cdprctl.geometry.kinematics import KinematicsData
from cdprctl.model.robot import RobotModel
from cdprctl.tda.solver import TensionDistributor
from cdprctl.tda.types import TDAMethod, TDAOptions, tda_options_of


def equilibrium_tensions(model: RobotModel, kin: KinematicsData) -> FloatArray:
    """Tensions (N) holding the platform's weight (and the jaws', eq. (46)) at the pose of
    ``kin``, as the robot's own distribution (``[control.tda]``) left them when it was parked:
    the brakes hold what was last commanded. Parked by another one, the controller would find
    other tensions than its own at enable and step its length targets by their stretch (rowc
    under SOTDA ν = 0.9 parked by the barycenter: 0.24 rad, a following-error fault at 1 kHz).
    The barycenter (QP for r != 2) where the robot's own cannot hold the pose alone; the
    minimum tensions when nothing can."""
    gs = GripperSet(model)
    R = kin.rotation
    weight, load = gs.at_rest(R)
    hold = -(model.gravity_wrench(R) + weight)
    wrench = gs.spring_wrench(kin.W, hold, load)
    k = model.cable_stiffness(kin.length)
    own = dataclasses.replace(tda_options_of(model), max_tension_rate=None)  # no history
    margin = model.control.tension_margin  # the controller's bounds (control/cycle/distribution.py)
    lo, hi = model.tension_min + margin, model.tension_max - margin
    out = TensionDistributor(model, own).solve(kin.W, wrench, lo, hi, k=k, kin=kin)
    if not out.ok:
        method = TDAMethod.BARYCENTER if model.redundancy == 2 else TDAMethod.QP
        out = TensionDistributor(model, TDAOptions(method=method)).solve(kin.W, wrench, k=k)
    t = out.tensions.copy() if out.ok else model.tension_min.copy()
    t[gs.cables] += load  # jB carries the jaws
    return t
