"""Inverse kinematics and the wrench matrix, with optional swivel pulleys.

Conventions (see also :mod:`cdprctl.core.rotation`):

* ``a_i`` (``model.anchors``): cable exit point on the frame, base frame. With a swivel pulley it
  is the point where the cable enters the pulley, on the swivel axis.
* ``b_i`` (``model.attachments``): attachment point on the platform, platform frame.
* ``u_i``: unit vector, base frame, from the platform attachment ``B_i = p + R b_i`` to the
  cable's exit point (``a_i``, or the pulley's tangent point): the direction a cable pulls the
  platform.
* Wrench matrix (Picard et al. 2020, eq. (2)): ``W = [u_i ; (R b_i) × u_i]`` (6×m), so that the
  cables exert the wrench ``W t`` (N, N·m; base frame, moments about ``P``) and the static
  equilibrium is ``W t + w_e + w_g = 0`` (Picard et al. 2020, eq. (1)).
* A displacement screw ``δX = [δp, δφ]`` (m, rad; base frame, rotation applied on the left)
  changes the cable lengths by ``δl = −Wᵀ δX``: ``Wᵀ`` is minus the length Jacobian. This holds
  with swivel pulleys too, with ``u_i`` pointing at the moving tangent point (the wrapped arc
  and the exit point's motion cancel to first order).

The functions fill a preallocated :class:`KinematicsData` (pinocchio's Model/Data split): the
loop allocates nothing. They never raise; degenerate geometry (a cable of zero length) yields
non-finite values that :func:`kinematics_ok` reports.

The arithmetic runs in a numba-compiled kernel: at 8 cables, numpy's per-call overhead
(0.6-3 µs per operation on these machines) cost 18-40 µs per IK; the kernel costs about 1 µs.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import numpy as np
from numba import njit

from cdprctl.core.numerics import kernel_args
from cdprctl.core.rotation import FloatArray


class CableLayout(Protocol):
    """What the kinematics needs of a robot: a ``RobotModel``, or the layout a telemetry
    client got from the daemon's status (``cdprctl.telemetry.foxglove.scene``)."""

    @property
    def n_cables(self) -> int: ...
    @property
    def anchors(self) -> FloatArray: ...
    @property
    def attachments(self) -> FloatArray: ...
    @property
    def pulley_radius(self) -> FloatArray: ...
    @property
    def pulley_axis(self) -> FloatArray: ...


class KinArrays(NamedTuple):
    """The arrays of one :class:`KinematicsData`, as the compiled kernels take them (the same
    objects: a kernel writes into the data's arrays; ``KinematicsData.arrays``, a plain tuple
    in this order, see ``numerics.kernel_args``). Inputs: ``anchors``, ``attach``,
    ``pulley_r``, ``pulley_axis``; outputs: the rest (see :func:`inverse_kinematics`)."""

    anchors: FloatArray
    attach: FloatArray
    pulley_r: FloatArray
    pulley_axis: FloatArray
    rbT: FloatArray
    exitT: FloatArray
    vT: FloatArray
    free_len: FloatArray
    wrap: FloatArray
    length: FloatArray
    W: FloatArray


class KinematicsData:
    """Workspace of the inverse kinematics of one robot; results of the last call.

    Per-cable vectors are stored coordinate-major, (3, m), and ``W`` (6, m) in C order.
    """

    def __init__(self, model: CableLayout):
        m = model.n_cables
        self.n_cables = m
        self.position = np.zeros(3)  # m, base frame
        self.rotation = np.eye(3)  # platform → base
        self.anchors = np.ascontiguousarray(model.anchors)  # (m, 3) base frame
        self.attachments = np.ascontiguousarray(model.attachments)  # (m, 3) platform frame
        self.pulley_radius = np.ascontiguousarray(model.pulley_radius)  # (m,) m
        self.pulley_axis = np.ascontiguousarray(model.pulley_axis)  # (m, 3) unit
        self.rbT = np.zeros((3, m))  # m, base frame: vectors P → B_i
        self.exitT = np.ascontiguousarray(model.anchors.T)  # m, base frame: exit points
        self.cable_vectorsT = np.zeros((3, m))  # m, base frame: B_i → exit point
        self.free_length = np.zeros(m)  # m, straight part exit point → B_i
        self.wrap_angle = np.zeros(m)  # rad, arc wrapped on the pulley (0 without pulley)
        self.length = np.zeros(m)  # m, free length + wrapped arc
        self.W = np.zeros((6, m))  # wrench matrix, C order
        self.WT = self.W.T  # (m, 6) view
        self.uT = self.W[:3]  # (3, m) unit vectors, base frame: B_i → exit point
        self.arrays = kernel_args(
            KinArrays(
                self.anchors,
                self.attachments,
                self.pulley_radius,
                self.pulley_axis,
                self.rbT,
                self.exitT,
                self.cable_vectorsT,
                self.free_length,
                self.wrap_angle,
                self.length,
                self.W,
            )
        )

    # Row-major (m, 3) views for callers that think per cable.
    @property
    def rb(self) -> FloatArray:
        """(m, 3) m, base frame: ``R b_i`` (view)."""
        return self.rbT.T

    @property
    def u(self) -> FloatArray:
        """(m, 3) unit vectors, base frame (view)."""
        return self.uT.T

    @property
    def exit_points(self) -> FloatArray:
        """(m, 3) m, base frame: exit points (anchors, or pulley tangent points) (view)."""
        return self.exitT.T

    @property
    def attach_points(self) -> FloatArray:
        """(m, 3) m, base frame: the attachment points ``B_i = p + R b_i`` (allocates)."""
        return self.rb + self.position


def inverse_kinematics(
    model: CableLayout, data: KinematicsData, position: FloatArray, rotation: FloatArray
) -> None:
    """Cable lengths, unit vectors and wrench matrix at the pose ``(position, rotation)``.

    Parameters
    ----------
    model : RobotModel
    data : KinematicsData
        Filled in place: ``rbT``, ``exitT``, ``cable_vectorsT``, ``free_length``,
        ``wrap_angle``, ``length`` (m), ``uT`` and ``W`` (Picard et al. 2020, eq. (2)).
    position : (3,) array
        Platform reference point ``P``, m, base frame.
    rotation : (3, 3) array
        Platform orientation, platform → base.
    """
    d = data
    d.position[:] = position
    d.rotation[:] = rotation
    ik_kernel(d.arrays, d.position, d.rotation)


@njit(cache=True, fastmath=False)
def ik_kernel(k, p, R):  # pragma: no cover - compiled; covered through inverse_kinematics
    """IK of every cable at the pose ``p``, ``R`` into the output arrays of ``k``
    (:class:`KinArrays`; see :func:`inverse_kinematics`)."""
    anchors, attach, pulley_r, pulley_axis, rbT, exitT, vT, free_len, wrap, length, W = k
    m = anchors.shape[0]
    for i in range(m):
        bx, by, bz = attach[i, 0], attach[i, 1], attach[i, 2]
        rx = R[0, 0] * bx + R[0, 1] * by + R[0, 2] * bz
        ry = R[1, 0] * bx + R[1, 1] * by + R[1, 2] * bz
        rz = R[2, 0] * bx + R[2, 1] * by + R[2, 2] * bz
        rbT[0, i], rbT[1, i], rbT[2, i] = rx, ry, rz
        Bx, By, Bz = p[0] + rx, p[1] + ry, p[2] + rz
        ax, ay, az = anchors[i, 0], anchors[i, 1], anchors[i, 2]
        r = pulley_r[i]
        if r > 0.0:
            # Swivel pulley (Pott, Cable-Driven Parallel Robots, Springer 2018, §2.5): in the
            # plane of the swivel axis z and the radial direction e towards B, wheel centre
            # C = a + r e; the cable enters at (−r, 0) travelling along +z, wraps over the wheel
            # and leaves at the tangent point of polar angle φ = atan2(bz, bx) + acos(r/|CB|);
            # the wrapped arc is β = π − φ.
            zx, zy, zz = pulley_axis[i, 0], pulley_axis[i, 1], pulley_axis[i, 2]
            dx, dy, dz = Bx - ax, By - ay, Bz - az
            along = dx * zx + dy * zy + dz * zz
            qx, qy, qz = dx - along * zx, dy - along * zy, dz - along * zz
            rho = math.sqrt(qx * qx + qy * qy + qz * qz)
            if rho > 1e-12:
                ex, ey, ez = qx / rho, qy / rho, qz / rho
            else:  # B on the swivel axis: the swivel angle is undefined, take any normal
                if abs(zx) < 0.9:
                    ex, ey, ez = 0.0, zz, -zy
                else:
                    ex, ey, ez = -zz, 0.0, zx
                nrm = math.sqrt(ex * ex + ey * ey + ez * ez)
                ex, ey, ez = ex / nrm, ey / nrm, ez / nrm
            cbx, cbz = rho - r, along
            dist = math.sqrt(cbx * cbx + cbz * cbz)
            ratio = r / dist if dist > r else 1.0
            phi = math.atan2(cbz, cbx) + math.acos(ratio)
            c, s = r + r * math.cos(phi), r * math.sin(phi)
            tx, ty, tz = ax + c * ex + s * zx, ay + c * ey + s * zy, az + c * ez + s * zz
            wrap[i] = math.pi - phi
        else:
            tx, ty, tz = ax, ay, az
            wrap[i] = 0.0
        exitT[0, i], exitT[1, i], exitT[2, i] = tx, ty, tz
        vx, vy, vz = tx - Bx, ty - By, tz - Bz
        vT[0, i], vT[1, i], vT[2, i] = vx, vy, vz
        lf = math.sqrt(vx * vx + vy * vy + vz * vz)
        free_len[i] = lf
        length[i] = lf + r * wrap[i]
        ux, uy, uz = vx / lf, vy / lf, vz / lf
        W[0, i], W[1, i], W[2, i] = ux, uy, uz
        W[3, i] = ry * uz - rz * uy
        W[4, i] = rz * ux - rx * uz
        W[5, i] = rx * uy - ry * ux


def kinematics_ok(data: KinematicsData, min_length: float = 1e-6) -> bool:
    """True when every cable has a finite length above ``min_length`` (m)."""
    # min() propagates NaN and NaN > x is False: one reduction checks both.
    return bool(min(data.free_length.tolist()) > min_length) and not any(
        math.isnan(x) for x in data.free_length.tolist()
    )


def cable_lengths(model: CableLayout, position: FloatArray, rotation: FloatArray) -> FloatArray:
    """Convenience (allocating) form: total cable lengths (m) at a pose."""
    data = KinematicsData(model)
    inverse_kinematics(model, data, position, rotation)
    return data.length.copy()


def wrench_matrix(model: CableLayout, position: FloatArray, rotation: FloatArray) -> FloatArray:
    """Convenience (allocating) form: the wrench matrix W (6×m) at a pose."""
    data = KinematicsData(model)
    inverse_kinematics(model, data, position, rotation)
    return np.array(data.W)
