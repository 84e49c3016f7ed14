"""The simulated experiments of Sensors 2019, 19, 3403, §4, with our plant and our controller in
lock-step (deterministic): the tension planner of §4.1 and the gripper sweeps of §4.2, and a
grasp-sensing sweep over object sizes and stiffnesses. Used by the tests
(tests/test_gripper_loop.py), `tools/gripper_figures.py` and `cdprctl report`.

The paper's external load is ``F_ext = [200, 0, −1470 | −500, 0, 0]`` with ``−1470 N`` the
platform's weight (which our plant's gravity gives) and the moment read in N·mm, as its own
tables need (config/seed000.toml): the plant receives ``[200, 0, 0 | −0.5, 0, 0]`` at ``P``,
ramped in over 2 s, and the controller knows it (fed forward, as the paper's planner assumed).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from cdprctl.control.command_types import GripKind, GripperCommand
from cdprctl.control.states import State
from cdprctl.experiments.closed_loop import ClosedLoop
from cdprctl.geometry.gripper_mechanics import GraspState
from cdprctl.model.robot import RobotModel
from cdprctl.tda import ImposedQuantity, Imposition

PAPER_EXT = (200.0, 0.0, 0.0, -0.5, 0.0, 0.0)  # N, N·m at P, base frame (besides gravity)
RAMP = 2.0  # s


class ExperimentError(RuntimeError):
    pass


def _loop(model: RobotModel, ext: tuple[float, ...]) -> ClosedLoop:
    """A started, enabled closed loop with ``ext`` ramped in and fed forward, the energy TDA
    from the start (the plant is parked in the controller's distribution: the springs' stretch
    the pose estimate assumes is then the one they have)."""
    if model.control.tda_method != "energy":
        model = dataclasses.replace(
            model, control=dataclasses.replace(model.control, tda_method="energy")
        )
    cl = ClosedLoop(model)
    cl.startup()
    cl.command("enable")
    target = np.array(ext, dtype=float)
    t0 = cl.net.time

    def ramp(loop: ClosedLoop) -> None:
        s = min(1.0, (loop.net.time - t0) / RAMP)
        loop.plant.ext_force[:] = s * target[:3]
        loop.plant.ext_moment[:] = s * target[3:]
        loop.controller.ext_wrench[:] = s * target  # the jaws' weight the controller adds

    cl.run(RAMP + 3.0, each=ramp, record=False)
    _check(cl, "settling under the external wrench")
    return cl


def _check(cl: ClosedLoop, what: str) -> None:
    c = cl.controller
    if c.data.state not in (State.ENABLED, State.MOVING):
        cl.close()
        events = "; ".join(f"{t:.3f} s {e}" for t, e in list(c.data.events)[-6:])
        d = c.data
        raise ExperimentError(f"{what}: controller {d.state.value}: {d.fault_reason} ({events})")


def spring_deformation(cl: ClosedLoop, cable: int) -> float:
    """m: the plant's cable stretch (the spring's, cables being inextensible) at the last step."""
    return float(cl.plant.cable_lengths[cable] - cl.plant.unstretched_length()[cable])


def tension_planner(
    model: RobotModel,
    sweep: float = 20.0,
    cable_swept: int = 0,
    cable_held: int = 7,
    held_deformation: float = 0.447,
) -> dict[str, Any]:
    """§4.1: the energy TDA holds ``cable_held``'s deformation (m) while ``cable_swept``'s
    imposed energy goes from its minimum to its maximum feasible value in ``sweep`` seconds,
    the platform held in its pose by the loop (the paper fixed it in the simulator)."""
    cl = _loop(model, PAPER_EXT)
    c = cl.controller
    # the held cable's deformation is brought to its value in 3 s: a step of a soft cable's
    # tension is a step of its stretch, which the pose estimate cannot follow
    k_held = float(model.cable_stiffness(c.estimator.kin.length)[cable_held])
    d_start = float(c.data.tensions[cable_held]) / k_held
    t_start = cl.net.time

    def bring(loop: ClosedLoop) -> None:
        s = min(1.0, (loop.net.time - t_start) / 3.0)
        d = d_start + s * (held_deformation - d_start)
        held_now = Imposition(cable_held, ImposedQuantity.DEFORMATION, d)
        loop.controller.distribution.impose((held_now,))

    cl.run(6.0, each=bring, record=False)
    _check(cl, "holding the imposed deformation")
    held = Imposition(cable_held, ImposedQuantity.DEFORMATION, held_deformation)
    u_lo, u_hi = (float(x) for x in c.distribution.current.out.energy_range[cable_swept])
    k = float(model.cable_stiffness(c.estimator.kin.length)[cable_swept])
    # from where cable 1 is, down to its minimum energy in 3 s: the sweep starts there
    u_now = float(c.data.tensions[cable_swept]) ** 2 / (2.0 * k)
    t_down = cl.net.time

    def down(loop: ClosedLoop) -> None:
        s = min(1.0, (loop.net.time - t_down) / 3.0)
        imp = Imposition(cable_swept, ImposedQuantity.ENERGY, u_now + s * (u_lo - u_now))
        loop.controller.distribution.impose((held, imp))

    cl.run(5.0, each=down, record=False)
    _check(cl, "bringing the swept cable to its minimum energy")
    t0 = cl.net.time
    log: dict[str, list[float]] = {
        k_: []
        for k_ in ("t", "u_imposed", "t_desired", "t_plant", "held_def", "pos_err", "ang_err")
    }
    home = model.home

    def plan(loop: ClosedLoop) -> None:
        s = min(1.0, max(0.0, (loop.net.time - t0) / sweep))
        u = u_lo + s * (u_hi - u_lo)
        imp = Imposition(cable_swept, ImposedQuantity.ENERGY, u)
        loop.controller.distribution.impose((held, imp))
        p = loop.plant
        log["t"].append(loop.net.time - t0)
        log["u_imposed"].append(u)
        log["t_desired"].append(math.sqrt(2.0 * k * u))
        log["t_plant"].append(float(p.tension[cable_swept]))
        log["held_def"].append(spring_deformation(loop, cable_held))
        log["pos_err"].append(float(np.linalg.norm(p.position - home.position)))
        dR = p.R @ home.rotation.T
        log["ang_err"].append(float(math.acos(max(-1.0, min(1.0, (np.trace(dR) - 1) / 2)))))

    cl.run(sweep + 3.0, each=plan, record=False)
    _check(cl, "the tension planner")
    status = c.data.tda_status.name
    cl.close()
    out: dict[str, Any] = {key: np.array(v) for key, v in log.items()}
    out.update(u_range=(u_lo, u_hi), stiffness=k, tda_status=status)
    return out


def gripper_sweep(
    model: RobotModel,
    gripper: int = 0,
    object_travel: float | None = None,
    object_stiffness: float = math.inf,
    hold: dict[int, float] | None = None,
    travel_to: float | None = None,
    ext: tuple[float, ...] = PAPER_EXT,
) -> dict[str, Any]:
    """§4.2: gripper ``gripper`` driven by the energy TDA from its lowest feasible travel to
    ``travel_to`` (default: its highest) at the controller's gripper speed, the others held at
    ``hold`` (gripper → travel, m), with an object at ``object_travel`` (m, none if None).
    Logs the plant's jaw travel, spring deformation, cable tension and contact force, the
    actuator's work ``U = U_0 + ∫ τ dδ`` (J, with ``U_0`` eq. (36) at the start) and what the
    grasp sensor reports."""
    from cdprctl.geometry.gripper_mechanics import actuator_energy

    cl = _loop(model, ext)
    p, c = cl.plant, cl.controller
    p.set_object(gripper, object_travel if object_travel is not None else 10.0, object_stiffness)
    wait = 0.0
    for j, travel in (hold or {}).items():
        wait = max(wait, abs(travel - float(c.grippers.grasp.travel[j])) / c.grippers.GRIP_SPEED)
        c.submit(GripperCommand(gripper=j, grip=GripKind.TRAVEL, value=travel))
        cl.run(0.01, record=False)
    cl.run(wait + 2.0 if hold else 0.0, record=False)
    _check(cl, "moving the held grippers")
    lo, hi = c.grippers.travel_range(gripper)
    if not math.isfinite(lo):
        cl.close()
        raise ExperimentError("no feasible travel for the gripper here")
    c.submit(GripperCommand(gripper=gripper, grip=GripKind.TRAVEL, value=lo + 0.001))
    gr = c.grippers
    cl.run(max(abs(lo - gr.grasp.travel[gripper]) / gr.GRIP_SPEED, 0.0) + 4.0, record=False)
    _check(cl, "opening the gripper")
    end = min(hi, travel_to) if travel_to is not None else hi
    end -= 0.001
    c.submit(GripperCommand(gripper=gripper, grip=GripKind.TRAVEL, value=end))
    cable = int(c.grippers.set.cables[gripper])
    params = c.grippers.set.params(gripper, math.inf)
    d0 = spring_deformation(cl, cable)
    work = [actuator_energy(params, d0)]
    keys = ("t", "travel", "deformation", "tension", "contact", "state", "force_est", "travel_est")
    log: dict[str, list[Any]] = {k: [] for k in keys}
    t0 = cl.net.time
    last = [d0, float(p.tension[cable])]

    def record(loop: ClosedLoop) -> None:
        d = spring_deformation(loop, cable)
        tau = float(p.tension[cable])
        work.append(work[-1] + 0.5 * (tau + last[1]) * (d - last[0]))
        last[:] = [d, tau]
        log["t"].append(loop.net.time - t0)
        log["travel"].append(float(p.jaw_travel[gripper]))
        log["deformation"].append(d)
        log["tension"].append(tau)
        log["contact"].append(float(p.contact_force[gripper]))
        g = loop.controller.grippers.grasp
        log["state"].append(g.state[gripper].value)
        log["force_est"].append(float(g.force[gripper]))
        log["travel_est"].append(float(g.travel[gripper]))

    cl.run((end - lo) / c.grippers.GRIP_SPEED + 3.0, each=record, record=False)
    _check(cl, "closing the gripper")
    cl.close()
    out: dict[str, Any] = {k: np.array(v) for k, v in log.items()}
    out["energy"] = np.array(work[1:])
    out.update(range=(lo, hi), object_travel=object_travel, object_stiffness=object_stiffness)
    return out


def detection(run: dict[str, Any]) -> dict[str, float]:
    """Grasp-sensing figures of a ``gripper_sweep`` with an object: travel past the true
    contact when the sensor first left OPEN (m), and the force estimate's error at the end
    (N, mean of the last second, against the plant's contact force)."""
    L21 = run["object_travel"]
    closed = np.nonzero(run["state"] != GraspState.OPEN.value)[0]
    touched = np.nonzero(run["contact"] > 0.0)[0]
    if len(closed) == 0 or len(touched) == 0:
        return {"detected_after": math.nan, "false_early": math.nan, "force_error": math.nan}
    i = closed[0]
    t = run["t"]
    last = t >= t[-1] - 1.0
    return {
        "detected_after": float(run["travel"][i] - L21),  # m of travel past the object
        "false_early": float(run["t"][touched[0]] - run["t"][i]),  # s, > 0: said before it was
        "force_true": float(np.mean(run["contact"][last])),
        "force_error": float(np.mean(run["force_est"][last] - run["contact"][last])),
    }
