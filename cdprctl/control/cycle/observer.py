"""The external wrench, estimated from the platform's motion and the tensions the winches apply
(a generalised-momentum disturbance observer, as De Luca's collision observer for manipulators):

    r(t) = L (p(t) − p(0) − ∫ (W t_a + w_g + r) dτ),   p = [m v; I_w ω]

converges to the unknown external wrench ``w_e`` (N, N·m at P, base frame) as a first-order lag
of bandwidth ``L`` (rad/s), without differentiating the velocity. ``t_a``, the tensions applied,
come from the drives' measured motor torques less the winch model's friction and rotor inertia
(``torques.py``: the same law the torques were computed with), so a drive that does not deliver
is seen too.

The estimate is published (``ControlData.ext_estimate``, the ``state`` telemetry), not fed
forward: on the window-cleaning robot it converges to 25.2 N of a 30 N jet within 1 s at 2 Hz
(lock-step, open loop), but fed forward to the pose controller it destabilised the weak y
direction at every bandwidth tried (0.5-8 Hz, with and without the PID's integral; lock-step,
measured): the y force of the cables depends on a y position the encoders barely see (the
stretch under an unknown force), so the observer's own error closes a loop through the active
stiffness. docs/control.md has the figures.

The rotational part neglects ``ω × I_w ω`` (the platform turns slowly) and takes the momentum
about P (``com`` offsets are small on the shipped robots); both go into the estimate as a small
error the PID's integral removes.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from cdprctl.control.cycle.cycle_io import PoseArgs
from cdprctl.control.cycle.pd_kernel import Platform
from cdprctl.control.cycle.tension_source import cable_tension
from cdprctl.control.cycle.torques import WinchTorques, applied_tension
from cdprctl.control.data import ControlData
from cdprctl.core.numerics import cycle_kernel, kernel_args
from cdprctl.geometry.kinematics import KinematicsData
from cdprctl.model.robot import RobotModel


class ObserverState(NamedTuple):
    """The estimate ``w_hat`` (6,), the momentum at the start ``p0`` (6,), the integral of the
    known and estimated wrenches ``integral`` (6,), and ``scratch`` (m + 15,): the applied
    tensions, then the kernel's vectors (none built in the loop)."""

    w_hat: np.ndarray
    p0: np.ndarray
    integral: np.ndarray
    scratch: np.ndarray


@cycle_kernel
def momentum_kernel(mass, inertia, R, v, w, out):  # pragma: no cover - compiled
    """``out`` (6,) ← ``[m v; R I Rᵀ ω]`` (kg·m/s, kg·m²/s; base frame)."""
    for i in range(3):
        out[i] = mass * v[i]
        s = 0.0
        for j in range(3):
            Iw = 0.0
            for k in range(3):
                for n in range(3):
                    Iw += R[i, k] * inertia[k, n] * R[j, n]
            s += Iw * w[j]
        out[3 + i] = s


@cycle_kernel
def observer_kernel(
    dt, gain, platform, est, W, torque, velocity, accel_term, winches, state, cells
):  # pragma: no cover - compiled  # fmt: skip
    """One step of the observer (module docstring): the applied tensions from the measured
    ``torque`` (N·m) less friction at ``velocity`` (rad/s) and the rotor-inertia term
    ``accel_term`` (N·m, per winch), the wrench they exert with gravity, the integral, and
    ``w_hat`` from the momentum now. ``platform``: a ``Platform``; ``est``: the estimate, a
    ``PoseEstimate``; ``winches``: the ``WinchTerms``; ``state``: the ``ObserverState``;
    ``cells`` (N per cable): the load cells' tensions, taken where finite
    (``tension_source.cable_tension``)."""
    w_hat, p0, integral, scratch = state
    r, viscous, coulomb, stribeck, capstan = winches[:5]
    _, mass, inertia, com, gravity = platform
    R, v, w = est[1], est[2], est[3]
    m = torque.shape[0]
    t_a, rc, f, p = scratch[:m], scratch[m : m + 3], scratch[m + 3 : m + 9], scratch[m + 9 :]
    for i in range(m):
        t_a[i] = cable_tension(
            applied_tension(torque[i], viscous[i], coulomb[i], stribeck[i], capstan[i],
                            velocity[i], accel_term[i], r[i]),
            cells[i],
        )  # fmt: skip
    # known forces on the platform: cables and gravity (moment about P: (R c) × m g)
    for i in range(3):
        rc[i] = R[i, 0] * com[0] + R[i, 1] * com[1] + R[i, 2] * com[2]
    for a in range(3):
        f[a] = mass * gravity[a]
    f[3] = rc[1] * f[2] - rc[2] * f[1]
    f[4] = rc[2] * f[0] - rc[0] * f[2]
    f[5] = rc[0] * f[1] - rc[1] * f[0]
    for a in range(6):
        s = f[a] + w_hat[a]
        for i in range(m):
            s += W[a, i] * t_a[i]
        integral[a] += s * dt
    momentum_kernel(mass, inertia, R, v, w, p)
    for a in range(6):
        w_hat[a] = gain * (p[a] - p0[a] - integral[a])


class WrenchObserver:
    """``[control] observer_bandwidth`` Hz (0: off): the estimate is ``data.ext_estimate``,
    from the estimate (a ``PoseEstimate`` bundle and its ``KinematicsData``) given each call."""

    def __init__(self, model: RobotModel, data: ControlData,
                 winches: WinchTorques | None = None):  # fmt: skip
        """``winches``: the torque law's terms it takes back out of the measured torques —
        the controller's, so that a friction calibration applied to them reaches it too
        (None: the model's own)."""
        c = model.control
        self.model = model
        self.data = data
        self.gain = 2.0 * math.pi * c.observer_bandwidth  # rad/s
        # in position mode the measured tensions give the external wrench (cable_space.py)
        self.enabled = self.gain > 0.0 and not model.drives.holds_lengths
        pf = model.platform
        self._mass = float(pf.mass)
        self._inertia = np.ascontiguousarray(pf.inertia, dtype=float)
        self._gravity = np.ascontiguousarray(model.gravity, dtype=float)
        self._com = np.ascontiguousarray(pf.com, dtype=float)
        m = model.n_cables
        winches = winches if winches is not None else WinchTorques(model)
        self.winches = winches  # its terms read each call: a friction calibration replaces them
        self._platform = kernel_args(Platform(
            np.ascontiguousarray(model.home.rotation, dtype=float), self._mass, self._inertia,
            self._com, self._gravity,
        ))  # fmt: skip
        self._rotor_term = winches.rotor_term
        self._accel_term = np.zeros(m)  # N·m: J θ̈_d of the torques' feedforward
        self._state = kernel_args(
            ObserverState(np.zeros(6), np.zeros(6), np.zeros(6), np.zeros(m + 15))
        )
        self._last_t = math.nan
        self._no_cells = np.full(m, math.nan)  # N: no load cell on any cable

    def warm_up(self, estimate: PoseArgs, kin: KinematicsData) -> None:
        """Compile the kernels (``warm_up.py``), leaving the estimate at zero."""
        enabled, self.enabled, self._last_t = self.enabled, True, 0.0
        m = self.model.n_cables
        self.reset(estimate)
        self._last_t = 0.0
        self.update(self.model.control.period, np.zeros(m), np.zeros(m), np.zeros(6), estimate,
                    kin)  # fmt: skip
        self.enabled = enabled
        self.reset(estimate)
        self._state[0][:] = 0.0

    def reset(self, estimate: PoseArgs) -> None:
        """Start from zero at the ``estimate``'s momentum (enable: the platform at rest on
        its holding tensions)."""
        _, R, v, w = estimate
        w_hat, p0, integral, _ = self._state
        w_hat[:] = 0.0
        integral[:] = 0.0
        self.data.ext_estimate[:] = 0.0
        momentum_kernel(self._mass, self._inertia, R, v, w, p0)
        self._last_t = math.nan

    def update(self, t: float, torque: np.ndarray, velocity: np.ndarray,
               acceleration: np.ndarray, estimate: PoseArgs, kin: KinematicsData,
               cells: np.ndarray | None = None) -> None:  # fmt: skip
        """One step at time ``t`` (s) from the drives' measured ``torque`` (N·m) and
        ``velocity`` (rad/s) at the ``estimate`` (its wrench matrix in ``kin``);
        ``acceleration``: the trajectory's (the torques' rotor-inertia feedforward,
        subtracted as applied); ``cells`` (N per cable, NaN: none): the load cells'."""
        if not self.enabled:
            return
        dt = t - self._last_t
        self._last_t = t
        if not 0.0 < dt < 0.1:
            return  # the first step after reset, or a gap: the integral starts here
        self._rotor_term(kin.WT, acceleration, self._accel_term)
        observer_kernel(
            dt, self.gain, self._platform, estimate, kin.W, torque, velocity,
            self._accel_term, self.winches.terms, self._state,
            self._no_cells if cells is None else cells,
        )  # fmt: skip
        np.copyto(self.data.ext_estimate, self._state[0])  # no view built
