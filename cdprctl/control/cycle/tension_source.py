"""Where a cable's tension comes from, and the load cells' supervision.

A cable with a load cell (``[[sensors.load_cells]]``, read by ``drivers/load_cells.py``) is
measured: its tension is the cell's, not the one taken back from its drive's torque through
the winch model (``torques.applied_tension``: friction off the file, pulley losses and the
rotor's inertia are its error). ``cable_tension`` is that rule, written once, for every part
that reads a cable's tension: the external-wrench estimate and the force feedback of position
mode (``cable_kernels.measured_tension_kernel``), the cable supervision (its internal tension
error), and the observer of torque mode (``observer.observer_kernel``). A cell that is not
heard within its timeout reads NaN: the torque's estimate takes over at once.

``LoadCellCheck`` watches the cells while the drives hold the platform (docs/safety.md, "Load
cells"), each a ``FaultKind.LOAD_CELL`` (the controller raises it) that names the cell, its
measured value and its limit:

* dead: no value within its ``timeout`` (its own liveness: the timeout is the persistence);
* disagreeing: the cell and the torque's estimate, each low-passed at ``FILTER``, further apart
  than both their errors (``accuracy`` + ``[sensors] estimate_error``) for
  ``[sensors] disagreement_time`` — a drifting or a knocked cell, or a drive that does not
  deliver. A cell's noise and a transient (a move's rotor inertia, a frame lost) ride through.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from cdprctl.control.cycle.torques import applied_tension
from cdprctl.control.supervision.persistence import Persistence
from cdprctl.core.numerics import cycle_kernel
from cdprctl.model.robot import RobotModel


@njit(cache=True)
def cable_tension(from_torque, cell):  # pragma: no cover - compiled
    """N: a cable's tension — its load cell's ``cell`` (N) where it has one that is alive
    (finite), else ``from_torque`` (N, the winch model's, ``torques.applied_tension``)."""
    return cell if math.isfinite(cell) else from_torque


@cycle_kernel
def disagreement_kernel(cells, torque, velocity, accel_term, winches, measured, alpha,
                        estimate_f, measured_f, bound):  # pragma: no cover - compiled  # fmt: skip
    """For each cell ``k`` on cable ``cells[k]``: the tension its drive's ``torque`` (N·m)
    applies at ``velocity`` (rad/s), less the rotor's inertia ``accel_term`` (N·m)
    (``torques.applied_tension``; ``winches``: the ``WinchTerms``) and the cell's
    ``measured`` (N), each low-passed by ``alpha`` into ``estimate_f`` and ``measured_f``
    (N). Returns the cell furthest beyond its ``bound`` (N) apart (-1: none), or ``-2 - k``
    for the first dead one (NaN: not heard within its timeout)."""
    r, viscous, coulomb, stribeck, capstan = winches[:5]
    worst, excess = -1, 0.0
    for k in range(cells.shape[0]):
        i = cells[k]
        if not math.isfinite(measured[i]):
            return -2 - k
        t = applied_tension(torque[i], viscous[i], coulomb[i], stribeck[i], capstan[i],
                            velocity[i], accel_term[i], r[i])  # fmt: skip
        if math.isfinite(estimate_f[k]) and math.isfinite(measured_f[k]):
            estimate_f[k] += alpha * (t - estimate_f[k])
            measured_f[k] += alpha * (measured[i] - measured_f[k])
        else:  # the first sample: the filters start there
            estimate_f[k], measured_f[k] = t, measured[i]
        d = abs(measured_f[k] - estimate_f[k]) - bound[k]
        if d > excess:
            worst, excess = k, d
    return worst


class LoadCellCheck:
    """The load cells' supervision (module docstring); ``check`` once a cycle while the drives
    hold the platform, ``reset`` when they start to."""

    #: Hz: the low-pass both sides of the comparison go through (a cell's noise, a lost frame)
    FILTER = 20.0

    def __init__(self, model: RobotModel, winches: object):
        """``winches``: the controller's ``WinchTorques`` (its ``terms``, the torque law)."""
        s = model.sensors
        self.cells = s.load_cells
        self.index = np.array([c.cable for c in self.cells], dtype=np.int64)
        self.bound = np.array([c.accuracy + s.estimate_error for c in self.cells])  # N
        self.estimate_error = s.estimate_error
        self.terms = winches.terms  # type: ignore[attr-defined]
        self.estimate_f = np.full(len(self.cells), math.nan)  # N
        self.measured_f = np.full(len(self.cells), math.nan)  # N
        self.apart = Persistence(s.disagreement_time)
        # s: after enabling, the drives' torque is the tension once the brakes are open
        # ([drives] brake_release_time, as the measured tensions of position mode)
        self.release = model.drives.brake_release_time
        self._since = 0.0  # s since reset
        self._last_t = math.nan

    def reset(self) -> None:
        """The filters start afresh (enabling: the first samples start them)."""
        self.estimate_f.fill(math.nan)
        self.measured_f.fill(math.nan)
        self.apart.held(0.0, False)
        self._since = 0.0
        self._last_t = math.nan

    def check(self, t: float, torque: np.ndarray, velocity: np.ndarray, accel_term: np.ndarray,
              measured: np.ndarray) -> str:  # fmt: skip
        """At ``t`` (s) from the drives' ``torque`` (N·m), ``velocity`` (rad/s), the rotor's
        inertia ``accel_term`` (N·m per winch, ``WinchTorques.rotor_term``: on CoGiRo 40 N of
        tension per m/s² of cable) and the cells' ``measured`` tensions (N per cable, NaN:
        none or dead): why a cell is a fault now ("" while none is)."""
        if not self.cells:
            return ""
        dt = t - self._last_t if math.isfinite(self._last_t) else 0.0
        self._last_t = t
        self._since += dt
        alpha = 1.0 - math.exp(-2.0 * math.pi * self.FILTER * max(dt, 0.0))
        k = disagreement_kernel(self.index, torque, velocity, accel_term, self.terms, measured,
                                alpha, self.estimate_f, self.measured_f, self.bound)  # fmt: skip
        if k >= 0 and self._since <= self.release:
            k = -1  # the brakes may still hold part of the load: not the torque's yet
        if k <= -2:
            c = self.cells[-2 - k]
            return (f"load cell of cable index {c.cable} (node {c.node_id}, bus {c.bus}) dead: "
                    f"no value within its timeout {c.timeout * 1e3:g} ms")  # fmt: skip
        if not self.apart.held(t, k >= 0) or k < 0:
            return ""
        c, cell, torque_n = self.cells[k], self.measured_f[k], self.estimate_f[k]
        return (
            f"load cell of cable index {c.cable} (node {c.node_id}) and its drive's torque "
            f"disagree: {cell:.1f} N measured by the cell, {torque_n:.1f} N from the torque, "
            f"{abs(cell - torque_n):.1f} N "
            f"apart for {self.apart.duration * 1e3:g} ms, beyond both their errors "
            f"({c.accuracy:g} N accuracy + {self.estimate_error:g} N estimate_error)"
        )  # fmt: skip

    def warm_up(self) -> None:
        """The kernel once on throwaway state (compiled before the drives start)."""
        z = np.zeros(self.terms[0].shape[0])
        disagreement_kernel(self.index, z, z, z, self.terms, z, 0.5, self.estimate_f.copy(),
                            self.measured_f.copy(), self.bound)  # fmt: skip
