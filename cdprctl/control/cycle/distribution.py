"""The tension distribution in the loop: the distributor in use, the one the stretch estimate
uses, and the switch between methods (Picard et al. 2020, Fig. 3: the TDA between the pose
controller and the winches).

Every distributor the robot can switch to is built here, at start-up, two of each method
(``BANKS``): a switch (``set_tda``, ``impose``) swaps references and sets options in place,
so the cycle builds nothing. The old pair stays in the other bank and blends out over
``BLEND_TIME``: both hold the wrench, so every blend does, inside the limits (a convex set).
With grippers the TDA works on the springs' tensions τ_A (jB's load added back, Sensors 2019
eq. (26)).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from cdprctl.control.cycle.reference_pose import WorkingPose
from cdprctl.control.data import ControlData
from cdprctl.core.rotation import FloatArray
from cdprctl.geometry.gripper_mechanics import GripperSet
from cdprctl.model.robot import RobotModel
from cdprctl.tda import (
    Imposition,
    TDAMethod,
    TDAOptions,
    TDAOutput,
    TDAStatus,
    TensionDistributor,
)
from cdprctl.tda.planar import feasible_scale_kernel
from cdprctl.tda.types import ENERGY, IMPOSITION_INFEASIBLE, INFEASIBLE, OK

BANKS = 2


def usable(status: TDAStatus) -> bool:
    """Tensions the loop may command: feasible, or feasible with an imposition saturated."""
    return status is OK or status is IMPOSITION_INFEASIBLE


class Distribution:
    # A new distribution takes over in this time. A step from the barycenter to the minimum of
    # energy moved seed000's soft cables by 10-20 N, 1-2 cm of stretch the pose estimate took
    # for an encoder fault at once (lock-step, tests/experiments/test_closed_loop_seed000.py).
    BLEND_TIME = 1.0  # s

    def __init__(
        self,
        model: RobotModel,
        data: ControlData,
        grippers: GripperSet,
        options: TDAOptions,
    ):
        c = model.control
        m = model.n_cables
        self.model = model
        self.data = data
        self.grippers = grippers
        self.t_min = model.tension_min + c.tension_margin  # N
        self.t_max = model.tension_max - c.tension_margin  # N
        errors = options.validate(model)
        if errors:
            raise ValueError("invalid TDA options: " + "; ".join(errors))
        self.methods = tuple(
            x for x in TDAMethod if not TDAOptions(method=x, period=c.period).validate(model)
        )
        # _pool[bank][method] = (the loop's distributor, the stretch estimate's)
        self._pool = [
            {
                x: tuple(
                    TensionDistributor(model, TDAOptions(method=x, period=c.period))
                    for _ in range(2)
                )
                for x in self.methods
            }
            for _ in range(BANKS)
        ]
        self._bank = 0
        self.current, self.static = self._pool[0][options.method]
        self.current.set_options(options)
        self.static.set_options(options)
        self.old: TensionDistributor | None = None  # blending out, with its static twin
        self.old_static: TensionDistributor | None = None
        self.blend_start = -np.inf
        self.bad_cycles = 0
        self._spring_prev = np.zeros(m)
        self._blend_old = np.zeros(m)
        # saturation (distribute): the feed-forward wrench, the saturated one, the particular
        # solutions of both parts and the polygon's scratch
        self.r = model.redundancy
        self._w_ff = np.zeros(6)
        self._w_sat = np.zeros(6)
        self._t_ff = np.zeros(m)
        self._t_fb = np.zeros(m)
        self._t_s = np.zeros(m)
        self._verts = np.zeros((2 * m + 8, 2))
        self._verts_tmp = np.zeros((2 * m + 8, 2))
        self._bounds = np.zeros((3, m))  # the polygon's strips (feasible_scale_kernel)
        data.tda_method = options.method.value

    @property
    def options(self) -> TDAOptions:
        return self.current.options

    # -- switching (in the cycle: references and options only) ------------------------------------
    def switch(self, options: TDAOptions, t: float, blend: bool) -> None:
        """Use ``options`` (validated for this robot) from this cycle on; ``blend``: the old
        distribution hands over over ``BLEND_TIME`` (the drives hold the platform)."""
        bank = (self._bank + 1) % BANKS
        new, new_static = self._pool[bank][options.method]
        new.set_options(options)
        new_static.set_options(options)
        if blend:
            self.old, self.old_static = self.current, self.static
            self.blend_start = t
        else:
            self.old = self.old_static = None
        self.current, self.static, self._bank = new, new_static, bank
        self.data.tda_method = options.method.value

    def impose(self, impositions: tuple[Imposition, ...]) -> None:
        """Switch the energy TDA's impositions (Sensors 2019 eq. (24)) from the next cycle,
        for the loop's and the stretch estimate's distribution alike (a tension planner calls
        it every cycle; values are the caller's to keep feasible and to ramp)."""
        base = self.current.options
        opts = dataclasses.replace(base, method=ENERGY, impositions=impositions)
        if base.method is not ENERGY:  # once: the energy TDA's set-up
            self.current, self.static = self._pool[self._bank][ENERGY]
            self.data.tda_method = ENERGY.value
        self.current.options = opts
        self.static.options = opts

    # -- solving -------------------------------------------------------------------------------
    def solve(
        self, tda: TensionDistributor, wrench: FloatArray, t_prev: FloatArray | None,
        at: WorkingPose,
    ) -> TDAOutput:  # fmt: skip
        """The TDA at the working pose ``at`` (the estimate, or the reference in position mode:
        ``reference_pose.py``), on the springs' tensions when there are grippers."""
        e, gs = at, self.grippers
        if gs.n:
            jb = self.data.jb_load
            wrench = gs.spring_wrench(e.kin.W, wrench, jb)
            if t_prev is not None:
                tp = self._spring_prev
                tp[:] = t_prev
                tp[gs.cables] -= jb
                t_prev = tp
        dt = self.data.dt if self.data.dt > 0.0 else None
        return tda.solve(
            e.kin.W, wrench, self.t_min, self.t_max, k=e.k, kin=e.kin, t_prev=t_prev, dt=dt
        )

    def total(self, spring: FloatArray, out: FloatArray) -> None:
        """Cable tensions (N) into ``out`` from the springs' ``spring``: ``τ = τ_A + τ_B``."""
        np.copyto(out, spring)  # no view built, as a slice would
        if self.grippers.n:
            out[self.grippers.cables] += self.data.jb_load

    def blend(
        self,
        old: TensionDistributor | None,
        wrench: FloatArray,
        t_prev: FloatArray | None,
        tensions: FloatArray,
        at: WorkingPose,
    ) -> None:
        """``tensions`` (the new distribution's, N) ← a blend with the old distribution's
        while a switch is under way; unchanged when the old one has nothing feasible."""
        if old is None:
            return
        s = (self.data.time - self.blend_start) / self.BLEND_TIME
        if s >= 1.0:
            self.old = self.old_static = None
            return
        out = self.solve(old, wrench, t_prev, at)
        if usable(out.status):
            old_total = self._blend_old
            self.total(out.tensions, old_total)
            tensions *= s
            tensions += (1.0 - s) * old_total

    def distribute(self, at: WorkingPose) -> TDAOutput:
        """``data.tensions`` for ``data.wrench`` at the working pose ``at``. A wrench the
        cables cannot produce is saturated: its feedback part (``data.feedback_wrench``)
        scaled down until it can (``data.saturation`` < 1, ``data.wrench`` the saturated one);
        when even the feed-forward cannot be held, the last feasible tensions are held (never
        outside the limits) and ``bad_cycles`` counts."""
        d = self.data
        # while a switch blends, the blend limits the tension rate: a rate limit on either
        # side would hold the commanded tensions back from the stretch estimate's (which has
        # none) and the pose estimate would see the difference as an encoder fault
        blending = self.old is not None
        t_prev = None if blending else d.tensions
        out = self.solve(self.current, d.wrench, t_prev, at)
        d.saturation = 1.0
        if out.status is INFEASIBLE:
            saturated = self._saturate(t_prev, at)
            if saturated is not None:
                out = saturated
        d.tda_status = out.status
        if usable(out.status):
            self.total(out.tensions, d.tensions)
            self.blend(self.old, d.wrench, None, d.tensions, at)
            np.copyto(d.hold_tensions, d.tensions)
            self.bad_cycles = 0
        else:
            d.tensions[:] = d.hold_tensions
            self.bad_cycles += 1
        return out

    def restart(self) -> None:
        """Command the last feasible tensions again, the feedback unsaturated (enable; the
        start-up's fixed point): what was saturated before a fault is not this run's."""
        np.copyto(self.data.tensions, self.data.hold_tensions)
        self.data.saturation = 1.0

    def _saturate(self, t_prev: FloatArray | None, at: WorkingPose) -> TDAOutput | None:
        """The solution for ``w_ff + s w_fb`` with the largest ``s`` in [0, 1] the cables can
        produce (``w_fb``: the PID's feedback wrench, ``w_ff`` the rest: weight, inertia, the
        known external wrench — never scaled); None when even ``s = 0`` is infeasible. For
        r = 2 exactly, by bisection on the feasible polygon's emptiness (``planar.
        feasible_scale_kernel``, ~20 polygons of a few µs); for other r by bisection on the
        distributor's own solve (8 solves)."""
        d, e, gs, dist = self.data, at, self.grippers, self.current
        ff = self._w_ff
        np.subtract(d.wrench, d.feedback_wrench, out=ff)
        if self.r == 2:
            ns = dist.ns  # factorised at this pose by the solve that failed
            if not ns.rank_ok:
                return None
            spring_ff = gs.spring_wrench(e.kin.W, ff, d.jb_load) if gs.n else ff
            ns.particular(spring_ff, self._t_ff)
            np.subtract(ns.t0, self._t_ff, out=self._t_fb)
            s = feasible_scale_kernel(
                ns.N, self._t_ff, self._t_fb, self.t_min, self.t_max, self._verts,
                self._verts_tmp, self._t_s, self._bounds,
            )  # fmt: skip
        else:
            s = self._scale_by_solving(ff, d.feedback_wrench, t_prev, at)
        if s < 0.0:
            return None
        w = self._w_sat
        np.multiply(d.feedback_wrench, s, out=w)
        w += ff
        out = self.solve(dist, w, t_prev, at)
        if not usable(out.status):
            return None
        d.saturation = s
        d.wrench[:] = w
        return out

    def _scale_by_solving(self, ff: FloatArray, fb: FloatArray, t_prev: FloatArray | None,
                          at: WorkingPose) -> float:  # fmt: skip
        """``_saturate``'s scale for r != 2: bisection on the distributor's own solve."""
        w = self._w_sat
        w[:] = ff
        if not usable(self.solve(self.current, w, t_prev, at).status):
            return -1.0
        a, b = 0.0, 1.0  # feasible at a, not at b
        for _ in range(8):
            s = 0.5 * (a + b)
            np.multiply(fb, s, out=w)
            w += ff
            if usable(self.solve(self.current, w, t_prev, at).status):
                a = s
            else:
                b = s
        return a

    def stretch(self, ff_wrench: FloatArray, at: WorkingPose) -> bool:
        """``data.stretch_tensions`` ← the static distribution of the feed-forward wrench
        ``ff_wrench`` at the working pose ``at``; False (unchanged) when it has none."""
        out = self.solve(self.static, ff_wrench, None, at)
        if not out.ok:
            return False
        self.total(out.tensions, self.data.stretch_tensions)
        self.blend(self.old_static, ff_wrench, None, self.data.stretch_tensions, at)
        return True
