"""The travel the redundancy can give one gripper at a pose (Sensors 2019, 19, 3403, §3.2: the
energy range of cable 1A with δ_8A imposed, eq. (17)-(20); eq. (38)-(39) as travel), used by
the controller before it accepts a gripper command and by the gateway for its reply."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.gripper_mechanics import GripperSet
from cdprctl.model.robot import RobotModel
from cdprctl.tda.solver import TensionDistributor
from cdprctl.tda.types import ImposedQuantity, Imposition, TDAMethod


def travel_range(
    model: RobotModel,
    tda: TensionDistributor,
    grippers: GripperSet,
    j: int,
    held: FloatArray,
    W: FloatArray,
    R: FloatArray,
    k: FloatArray,
    ext_wrench: FloatArray,
    t_min: FloatArray,
    t_max: FloatArray,
) -> tuple[float, float]:
    """(lo, hi) travel (m) of gripper ``j`` holding the static wrench at the pose of ``W``/``R``
    (gravity, ``ext_wrench`` N/N·m and the jaws' weight, eq. (46)) with the other grippers at
    ``held`` (m per gripper, NaN: free); NaN when nothing is feasible. ``tda`` is a scratch
    distributor whose options are replaced."""
    gs = grippers
    others = tuple(
        Imposition(int(gs.cables[i]), ImposedQuantity.DEFORMATION, float(held[i]))
        for i in range(gs.n)
        if i != j and math.isfinite(held[i])
    )
    tda.options = dataclasses.replace(
        tda.options, method=TDAMethod.ENERGY, impositions=others, max_tension_rate=None
    )
    weight, load = gs.at_rest(R)
    hold = -(model.gravity_wrench(R) + ext_wrench + weight)
    wrench = gs.spring_wrench(W, hold, load)
    out = tda.solve(W, wrench, t_min, t_max, k=k)
    if not out.ok:
        return math.nan, math.nan
    c = int(gs.cables[j])
    ka = float(gs.k_a[j])
    u = np.asarray(out.energy_range[c], dtype=float)
    return math.sqrt(2.0 * ka * float(u[0])) / ka, math.sqrt(2.0 * ka * float(u[1])) / ka
