"""Every compiled kernel the loop can call, compiled before the drives start.

numba compiles a kernel at its first call: seconds each on a machine that has not cached it
yet (~60 s in all on this VM). A compilation in the loop is a missed deadline; one between the
drives' start and the loop is a heartbeat timeout (a cold `cdprctl run --sim` faulted so).
Loading from numba's cache is also done at the first call: ~10 ms a kernel. So the start-up
calls each kernel once, on throwaway objects at the home pose, along every branch the loop can
take: each distribution method's, with and without the rate limit, and the energy method's
fast paths for one and two impositions (the grippers hold theirs from `enable` on).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from cdprctl.control.cycle.cable_kernels import (
    disturbance_kernel,
    force_feedback_kernel,
    tension_hold_kernel,
)
from cdprctl.control.cycle.estimator import Estimator
from cdprctl.core.numerics import count_kernel, largest, worst_ratio
from cdprctl.geometry.interference import relax_kernel
from cdprctl.tda import ImposedQuantity, Imposition, TDAMethod, TDAOptions, TensionDistributor
from cdprctl.tda.nullspace import NullSpace
from cdprctl.tda.planar import feasible_scale_kernel
from cdprctl.tda.polygon import least_violating

if TYPE_CHECKING:
    from cdprctl.control.cycle.controller import Controller


def _tda_variants(options: TDAOptions, r: int, mid: np.ndarray) -> list[TDAOptions]:
    """The options in use, and one of each compiled path the loop may switch to (``mid``:
    the middle of each cable's tension range, N, for the impositions)."""
    m = len(mid)
    rate = dataclasses.replace(options, max_tension_rate=options.max_tension_rate or 1e3)
    out = [options, rate, TDAOptions(method=TDAMethod.ENERGY, period=options.period)]
    if r == 2:
        out.append(TDAOptions(method=TDAMethod.SOTDA, nu=0.5, max_tension_rate=1e3))
        for n in (1, 2):
            imp = tuple(
                Imposition(c, ImposedQuantity.TENSION, float(mid[c])) for c in range(m - n, m)
            )
            out.append(TDAOptions(method=TDAMethod.ENERGY, impositions=imp))
    return out


def warm_up(controller: Controller) -> None:
    """Call every kernel of the cycle once (see the module docstring); leaves the controller
    as it was but for its outputs (wrench, pose error, torques: zero), rewritten each cycle."""
    c = controller
    d = c.data
    model = c.model
    m = model.n_cables
    zeros = np.zeros(m)
    est = Estimator(model)
    t_min, t_max = c.distribution.t_min, c.distribution.t_max
    # θ = 0: the home lengths. Writable arrays, as in the loop: numba compiles a read-only
    # array (the model's) as another type
    est.update(0.0, zeros, t_min.copy(), zeros, zeros)
    if c.grippers.n:
        c.grippers.warm_up()  # the jaws' loads: the weight wrench's kernel too
    hold = c.pose.gravity_hold(est.rotation, d.ext_total)  # any wrench: a kernel compiles whole
    prev = 0.5 * (t_min + t_max)
    for opts in _tda_variants(c.distribution.options, model.redundancy, prev):
        if opts.validate(model):
            continue  # not a method this robot can use
        tda = TensionDistributor(model, opts)
        for t_prev in (None, prev):
            tda.solve(est.kin.W, hold, t_min, t_max, k=est.k, kin=est.kin, t_prev=t_prev)
    # the saturation's kernels (distribution.py): a particular solution, one bisection
    ns = NullSpace(m)
    ns.update(est.kin.W, hold)
    t_ff = np.zeros(m)
    ns.particular(hold, t_ff)
    if model.redundancy == 2:
        verts = np.zeros((2 * m + 8, 2))
        feasible_scale_kernel(ns.N, t_ff, t_ff.copy(), t_min, t_max, verts, verts.copy(),
                              zeros.copy(), np.zeros((3, m)))  # fmt: skip
        least_violating(ns.N, ns.t0, t_min, t_max)  # a wrench no tensions can produce
    count_kernel(np.zeros(1, dtype=np.int64), 1)  # the cycle's count (controller._step_time)
    # not the cycle's but beside it: a jog's or a path's soft limits, checked by submit() in
    # the daemon's I/O thread while the loop runs (a compile there would hold the GIL)
    c.limits.check(np.tile(c.trajectory.position, (2, 1)))
    c.observer.warm_up(c.io.estimate, c.estimator.kin)
    c.load_cells.warm_up()
    c.pose.update(c.io.reference, c.io.working, d.ext_total, True, d.dt, c.io.wrench)
    c.pose.reset()
    c.winches.update(d.tensions, c.at.kin.WT, c.trajectory.acceleration, zeros, True,
                     d.torques)  # fmt: skip
    d.torques[:] = 0.0
    # the cable-space kernels (position mode), on throwaway outputs
    arrays = (d.motor_target, d.measured_tensions, d.tension_error, d.internal_tension_error,
              d.internal_leverage)  # fmt: skip
    saved = [a.copy() for a in arrays]
    offset = c.reference.offset.copy()
    c.reference.update(c.io.reference, c.estimator)  # the next cycle computes it afresh
    c.reference.offset[:] = offset
    ref = c.reference
    c.cable_space.targets(True, zeros, ref.reference_kin.length, ref.k, c.estimator.winding)
    c.cable_space.warm_up(ns.N, c.winches.terms)
    disturbance_kernel(est.kin.W, zeros, 0.0, np.zeros(6))
    force_feedback_kernel(zeros, np.ones(m), 0.5, np.zeros(m))
    tension_hold_kernel(zeros, np.ones(m), 0.5, 0.0, zeros, zeros, np.zeros(m))
    worst_ratio(zeros, np.ones(m))  # the supervisor's position-mode checks
    largest(zeros)  # the supervisor's feedback age
    relax_kernel(zeros, zeros.copy(), 0.0, 0.0)  # the supervisor's clearance, under it at start
    for a, v in zip(arrays, saved, strict=True):
        a[:] = v
    d.wrench[:] = 0.0
    d.pose_error[:] = 0.0
