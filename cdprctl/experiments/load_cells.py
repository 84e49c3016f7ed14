"""The external-wrench estimate under the 30 N water jet with and without load cells, on a
plant whose winches' friction is off the robot file (lock-step; issue 68's goal: within 0.5 N
with load cells). ``tools/load_cell_table.py`` prints the table of docs/results.md.

The run: enabled at home, the jet (30 N along y at P) ramped in over 1 s and held 4 s, then a
move of 0.3 m in x and −0.1 m in z under it. The estimate (``ControlData.ext_estimate``) is
compared with the wrench the plant applies: its force error's largest norm over the last
second of the hold (at rest) and over the move (the winches turning: friction acts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cdprctl.experiments.closed_loop import ClosedLoop, ramped_force
from cdprctl.model.robot import RobotModel

JET = 30.0  # N along y at P (ARK 2020's water jet)


@dataclass(frozen=True)
class JetRun:
    """One run's estimate errors (N: norm of the force part's error) and how it ended."""

    at_rest: float
    moving: float
    state: str
    fault: str


def friction_off(cl: ClosedLoop, seed: int, low: float = 0.3, high: float = 0.5) -> np.ndarray:
    """Each simulated winch's viscous and Coulomb friction scaled by ``1 ± U(low, high)``
    (sign and size drawn per winch from ``seed``), hidden from the controller; the scales."""
    rng = np.random.default_rng(seed)
    m = cl.model.n_cables
    scales = 1.0 + rng.choice([-1.0, 1.0], m) * rng.uniform(low, high, m)
    cl.plant.viscous *= scales  # in place: the physics' bundle holds these arrays
    cl.plant.coulomb *= scales
    return scales


def jet_run(model: RobotModel, seed: int | None, truth: RobotModel | None = None,
            identified: tuple[list[float], ...] | None = None) -> JetRun:  # fmt: skip
    """The run of the module docstring on ``model`` (``seed``: the winches' friction off the
    file by ``friction_off``; None: as the file says). ``truth``: the simulated winches'
    friction that robot's instead (``plant_errors.PlantErrors``, as ``calibrate friction
    --sim --plant-errors`` draws it); ``identified``: the friction the controller applies
    (viscous, Coulomb, Stribeck, pulley μ per winch: a friction calibration's, as ``run``
    applies the record's) in place of the file's."""
    with ClosedLoop(model) as cl:
        if seed is not None:
            friction_off(cl, seed)
        if truth is not None:  # in place: the physics' bundle holds these arrays
            for name, key in (("viscous", "viscous_friction"), ("coulomb", "coulomb_friction"),
                              ("stribeck", "stribeck_friction")):  # fmt: skip
                getattr(cl.plant, name)[:] = [getattr(c.winch, key) for c in truth.cables]
        if identified is not None:
            cl.controller.winches.apply_friction(*identified)
        d = cl.controller.data
        cl.startup()
        cl.command("enable")
        cl.run(1.0, record=False)
        jet = ramped_force(cl.net.time, JET)
        errors: list[float] = []

        def watch(c: ClosedLoop) -> None:
            jet(c)
            errors.append(float(np.linalg.norm(d.ext_estimate[:3] - c.plant.ext_force)))

        cl.run(4.0, each=jet, record=False)
        cl.run(1.0, each=watch, record=False)
        at_rest = max(errors)
        errors.clear()
        pose = np.concatenate([np.add(model.home.position, [0.3, 0.0, -0.1]), model.home.rpy])
        cl.command("move", pose=pose)
        cl.run(3.0, each=watch, record=False)
        return JetRun(at_rest, max(errors), d.state.value, d.fault_reason)
