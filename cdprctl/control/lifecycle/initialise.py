"""The start-up's fixed point: from the drives' first feedback, the pose (forward kinematics
from the home pose as a start) and the tensions holding it, found together and checked
holdable → READY. Outside the loop (``ControllerManager.startup``); raises on failure."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from cdprctl.control.states import State
from cdprctl.geometry.forward_kinematics import FKStatus
from drivers.vocabulary import WinchStates

if TYPE_CHECKING:
    from cdprctl.control.cycle.controller import Controller

MAX_ITERATIONS = 100
SETTLED = 1e-3  # N: the stretch tensions changed less than this in an iteration


def initialise(ctl: Controller, now: float, st: WinchStates) -> None:
    """The pose from the home pose as a start and the tensions holding it, checked holdable (a
    TDA under gravity) → READY. Raises RuntimeError, naming what failed."""
    d, e, dist, model = ctl.data, ctl.estimator, ctl.distribution, ctl.model
    e.reset(model.home.position, model.home.rotation)
    # The stretch depends on the tensions, which depend on the pose: a fixed point, from the
    # minimum tensions (soft cables, e.g. the Sensors 2019 springs, need a few iterations;
    # steel ones one or two).
    ctl.start_from(st.position)
    last = np.full(model.n_cables, np.inf)
    for _ in range(MAX_ITERATIONS):
        fk = e.update(now, st.position, d.stretch_tensions)
        if fk.status in (FKStatus.DEGENERATE, FKStatus.BAD_INPUT):
            raise RuntimeError(f"start-up: forward kinematics failed ({fk.status.name})")
        if ctl.at is ctl.reference:  # no reference yet: the estimate is the pose
            ctl.reference.hold(e.position, e.rotation)
        if ctl.grippers.n:
            ctl.grippers.update(st, sense=False)
        out = dist.solve(dist.current, ctl.pose.gravity_hold(e.rotation, d.ext_total), None, ctl.at)
        # on the way, a pose that cannot be held gives its least-violating tensions: the
        # fixed point goes on from them (from the minimum tensions, with the pose from six
        # cables, the first poses of the springy Sensors 2019 robot are far off)
        dist.total(out.tensions, d.hold_tensions)
        dist.total(out.tensions, d.stretch_tensions)
        if out.ok and d.cycle % ctl.stretch_every == 0:
            ctl.refresh_stretch_tensions()
        change = float(np.max(np.abs(d.stretch_tensions - last)))
        last[:] = d.stretch_tensions
        if change < SETTLED:
            break
    else:
        raise RuntimeError(
            f"start-up: pose and tensions did not settle in {MAX_ITERATIONS} iterations"
        )
    if not out.ok:
        p = e.position
        raise RuntimeError(
            f"start-up: the estimated pose [{p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}] m "
            f"cannot be held ({out.status.name}: {out.message})"
        )
    if fk.residual > model.control.max_fk_residual:
        raise RuntimeError(
            f"start-up: the encoders disagree with every pose "
            f"({fk.status.name}, residual {fk.residual:.3g} m)"
        )
    dist.restart()  # the holding tensions commanded
    e.velocity[:] = 0.0
    e.omega[:] = 0.0
    ctl.trajectory.reset(ctl.pose6())
    ctl.reference.update(ctl.io.reference, e)
    ctl.machine.request(State.READY, now, "drives inactive, feedback live, pose estimated")
