"""Picard et al., ARK 2020, §4 on the window-cleaning robot, in lock-step (deterministic):

* (a) the platform at X0 under a lateral force for ν = 0, 0.1 … 0.9 (the paper's Fig. 4 right:
  26-36 mm measured under 30 N, up to 24.8 % less than the barycenter);
* (b) a linear path followed under the force, t_max = 150 N, ν = 0 and ν = 0.9 (Fig. 5: no
  fault, tensions continuous, the cables that oppose the force near t_max at ν = 0.9, around
  the mean admissible tension at ν = 0), at 12.5, 30 and 50 N.

Each static deflection is compared with ``K⁻¹ δw`` (eq. (3)-(4)) at the commanded tensions,
the drives' position loops in series with the cables (``deflection_reference``).
``tools/ark2020_figures.py`` writes the tables and figures into docs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.geometry.stiffness import cable_stiffnesses, stiffness_matrix
from cdprctl.model import RobotModel
from cdprctl.tda import TDAMethod, TDAOptions
from sim_backend.faults import FaultEvent, FaultInjector

#: the lateral force's direction (the water jet, along y_b)
DIRECTION = (0.0, 1.0, 0.0)
#: the linear path of Fig. 5 (the paper draws it without coordinates): across the facade at
#: X0's height, 0.3 m either side of X0
PATH = ((1.2, 0.35, 0.59), (1.8, 0.35, 0.59))


def sotda(nu: float) -> TDAOptions:
    return TDAOptions(method=TDAMethod.SOTDA, nu=nu, direction=DIRECTION)


def uncompensated(model: RobotModel) -> RobotModel:
    """The robot without the external-wrench estimate fed forward and without the force
    feedback's give (position mode): an unknown force is held by the cables' elasticity
    alone, as by the paper's controller."""
    control = dataclasses.replace(model.control, disturbance_bandwidth=0.0, force_feedback=0.0)
    return dataclasses.replace(model, control=control)


def with_tension_max(model: RobotModel, t_max: float) -> RobotModel:
    """The robot with every cable's upper tension limit at ``t_max`` (N)."""
    cables = tuple(dataclasses.replace(c, tension_max=t_max) for c in model.cables)
    return dataclasses.replace(model, cables=cables)


def deflection_reference(model: RobotModel, position, tensions, force: float) -> float:
    """δy (m) = (K⁻¹ δw)_y for ``force`` N along y at ``position`` (home orientation), K = Kp +
    Ka at the ``tensions`` (N) (Picard et al. 2020, eq. (3)-(4)); with the drives in position
    mode each cable's spring in series with its drive's loop, kp/(r/G)² along the cable (the
    simulated drive's PD has no integral)."""
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, np.asarray(position, float), model.home.rotation)
    k = cable_stiffnesses(model, kin)
    if model.drives.holds_lengths:
        for i, c in enumerate(model.cables):
            r = c.winch.drum_radius / c.winch.gear_ratio
            kp = model.drives.position_gains(c.winch.rotor_inertia)[0]
            k[i] = 1.0 / (1.0 / k[i] + r * r / kp)
    dw = np.array([0.0, force, 0.0, 0.0, 0.0, 0.0])
    return float(np.linalg.solve(stiffness_matrix(model, kin, tensions, k), dw)[1])


@dataclass
class Static:
    """(a): one ν."""

    nu: float
    deflection: float  # m, the platform's final y displacement (the simulated truth)
    reference: float  # m, K⁻¹ δw at the commanded tensions
    tensions: np.ndarray  # N, commanded at the end
    state: str


def _force(cl: ClosedLoop, force: float) -> None:
    FaultInjector(
        [FaultEvent(cl.net.time, "external_wrench", value=(0, force, 0, 0, 0, 0), ramp=1.0)]
    ).attach(cl.net)


def static_under_force(model: RobotModel, nu: float, force: float = 30.0,
                       seconds: float = 4.0) -> Static:  # fmt: skip
    """Enable at X0 (the home pose), SOTDA with ``nu``, settle, ramp ``force`` N along y in
    over 1 s (unknown to the controller), hold ``seconds``. Use ``uncompensated(model)`` for
    the paper's experiment: with the estimate fed forward the deflection goes."""
    with ClosedLoop(model, sotda(nu)) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(1.5)
        y0 = float(cl.plant.position[1])
        _force(cl, force)
        cl.run(seconds)
        c = cl.controller
        y = float(np.mean(cl.arrays()["p_true"][-50:, 1])) - y0
        t = c.data.tensions.copy()
        ref = deflection_reference(model, cl.plant.position, t, force)
        return Static(nu, y, ref, t, c.data.state.value)


@dataclass
class PathRun:
    """(b): the path at one ν and force; per-cycle arrays."""

    nu: float
    force: float
    t: np.ndarray  # s
    tensions: np.ndarray  # N, commanded (n, m)
    p_true: np.ndarray  # m
    p_des: np.ndarray  # m
    state: str
    fault: str

    @property
    def max_error(self) -> float:
        return float(np.max(np.linalg.norm(self.p_true - self.p_des, axis=1)))

    @property
    def max_step(self) -> float:
        """N: the largest change of any commanded tension from one cycle to the next."""
        return float(np.max(np.abs(np.diff(self.tensions, axis=0))))


def path_under_force(model: RobotModel, nu: float, force: float) -> PathRun:
    """Enable at the path's start, SOTDA with ``nu``, the force ramped in over 1 s and 5 s
    more, then the path there and back at the robot's speed limits."""
    start, end = (np.array(p) for p in PATH)
    rpy = np.asarray(model.home.rpy, float)
    home = dataclasses.replace(model.home, position=start)
    with ClosedLoop(dataclasses.replace(model, home=home), sotda(nu)) as cl:
        cl.startup()
        cl.command("enable")
        cl.run(1.0, record=False)
        _force(cl, force)
        cl.run(6.0, record=False)  # the estimate of the force converges (~2 s at 0.5 Hz)
        for target in (end, start):
            cl.command("move", pose=np.concatenate([target, rpy]))
            cl.run(3.5)
        a = cl.arrays()
        c = cl.controller
        return PathRun(nu, force, a["t"], a["tensions"], a["p_true"], a["p_des"],
                       c.data.state.value, c.data.fault_reason)  # fmt: skip
