"""Pose control: the wrench the cables must exert, ``M (a_d + kp e + ki ∫e + kd ė) − w_g − w_e``
(PID on the pose error plus feed-forward of the trajectory's acceleration, gravity and the
known external wrench; the compiled kernel of ``pd_kernel.py``)."""

from __future__ import annotations

import math

import numpy as np

from cdprctl.control.cycle.cycle_io import PoseArgs, ReferenceArgs, WrenchArgs
from cdprctl.control.cycle.pd_kernel import Pid, Platform, pd_wrench_kernel
from cdprctl.core.numerics import kernel_args
from cdprctl.core.rotation import FloatArray
from cdprctl.model.robot import RobotModel


class PoseController:
    """The stage ``reference`` and working pose → ``wrench`` (``cycle_io.py``)."""

    def __init__(self, model: RobotModel):
        c = model.control
        self.model = model
        self.period = c.period
        bw = c.axis_bandwidth if c.axis_bandwidth is not None else (c.bandwidth,) * 6
        self.bandwidth = np.array(bw, dtype=float)  # Hz per axis (torque mode: set by hand)
        wn = 2.0 * math.pi * self.bandwidth  # rad/s per axis
        # PID by pole placement, a triple pole at −ω_n (s + ω)³: kp = 3ω², kd = 3ω, ki = ω³
        # (accelerations per m, per m/s, per m·s). The integral removes the PD's compliance
        # to a steady force (the water jet): what remains is the cables' own elasticity, the
        # stiffness the SOTDA acts on (Picard et al. 2020). damping_ratio scales kd. Per axis
        # (x, y, z, roll, pitch, yaw) when [control] axis_bandwidth is given.
        #
        # With the drives in position mode (cable_space.py) the pose feedback is off: the
        # drives' length loops are the feedback, and the pose the encoders give depends on the
        # tensions assumed for the stretch — with the commanded ones (what the drives realise)
        # a pose loop closes an algebraic loop (±40 mm of estimated y chattering on rowc at
        # 0.5 Hz), with measured ones a 0.1 N error is millimetres of y (28 mm during a move),
        # with the static feed-forward ones the internal forces differ (10-20 mm): each went
        # unstable during moves at 0.3 Hz and more (lock-step, measured; docs/control.md).
        on = 0.0 if model.drives.holds_lengths else 1.0
        self.kp = on * 3.0 * wn * wn
        self.kd = on * 3.0 * c.damping_ratio * wn
        self.ki = on * wn**3
        self.integral = np.zeros(6)  # m·s, rad·s
        # the integral term stays within 10 m/s² (rad/s²)
        self.integral_limit = on * 10.0 / np.maximum(wn**3, 1e-12)
        # contiguous float64 copies for the compiled kernel
        self._R_home = np.ascontiguousarray(model.home.rotation, dtype=float)
        self._inertia = np.ascontiguousarray(model.platform.inertia, dtype=float)
        self._com = np.ascontiguousarray(model.platform.com, dtype=float)
        self._gravity = np.ascontiguousarray(model.gravity, dtype=float)
        self._Rd = np.zeros((3, 3))
        self._E = np.zeros((3, 3))
        self._S = np.zeros(15)  # the kernel's vectors
        self._pid = kernel_args(Pid(self.kp, self.kd, self.ki, self.integral, self.integral_limit))
        platform = Platform(self._R_home, float(model.platform.mass), self._inertia, self._com,
                            self._gravity)  # fmt: skip
        self._platform = kernel_args(platform)

    def reset(self) -> None:
        self.integral[:] = 0.0

    def gravity_hold(self, R: FloatArray, ext_total: FloatArray) -> FloatArray:
        """The wrench (N, N·m at P, base frame) that holds the platform at rest at orientation
        ``R`` against gravity and the known external wrench ``ext_total``."""
        return -(self.model.gravity_wrench(R) + ext_total)

    def update(self, reference: ReferenceArgs, at: PoseArgs, ext_total: FloatArray,
               integrate: bool, dt: float, out: WrenchArgs) -> None:  # fmt: skip
        """``out`` (pose error, wrench, feedback part) for the trajectory's ``reference`` at
        the working pose ``at`` (the feedback closed on it; position mode: the reference,
        reference_pose.py says why; the feedback is off there), the known external wrench
        ``ext_total`` fed forward; the integral grows by ``dt`` (s) only when ``integrate``
        (holding or moving, not while enabling or stopping)."""
        pose_error, wrench, feedback = out
        pd_wrench_kernel(
            reference,
            at,
            self._pid,
            integrate,
            dt if dt > 0.0 else self.period,
            self._platform,
            ext_total,
            self._Rd,
            self._E,
            self._S,
            pose_error,
            wrench,
            feedback,
        )
