"""Inverse kinematics and the wrench matrix, with optional swivel pulleys.

Conventions (see also :mod:`cdprctl.rotation`):

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
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from cdprctl.rotation import FloatArray

if TYPE_CHECKING:
    from cdprctl.model.robot import RobotModel


class KinematicsData:
    """Workspace of the inverse kinematics of one robot; results of the last call.

    Per-cable vectors are stored coordinate-major, (3, m) or (5, m): rows ``[x, y, z, x, y]``
    make the cyclic permutations a cross product needs contiguous row blocks (``[1:4]`` = yzx,
    ``[2:5]`` = zxy). At 8 cables numpy's per-call overhead, not arithmetic, sets the cost, and
    contiguous operands take numpy's fast path (about 3x faster than strided views here).
    """

    def __init__(self, model: RobotModel):
        m = model.n_cables
        self.n_cables = m
        self.position = np.zeros(3)  # m, base frame
        self.rotation = np.eye(3)  # platform → base
        self._bT = np.ascontiguousarray(model.attachments.T)  # (3, m) platform frame
        self._r5 = np.zeros((5, 3))  # R with its first two rows repeated
        self._p5 = np.zeros((5, 1))
        self._rb5 = np.zeros((5, m))
        self._exit5 = np.zeros((5, m))
        self._exit5[:3] = model.anchors.T
        self._exit5[3:] = model.anchors.T[:2]
        self._v5 = np.zeros((5, m))
        self._tmp = np.zeros((3, m))
        self._inv_l = np.zeros(m)
        self.rbT = self._rb5[:3]  # (3, m) m, base frame: vectors P → B_i
        self.exitT = self._exit5[:3]  # (3, m) m, base frame: exit points
        self.cable_vectorsT = self._v5[:3]  # (3, m) m, base frame: B_i → exit point
        self.free_length = np.zeros(m)  # m, straight part exit point → B_i
        self.wrap_angle = np.zeros(m)  # rad, arc wrapped on the pulley (0 without pulley)
        self.length = np.zeros(m)  # m, free length + wrapped arc
        self.W = np.zeros((6, m))  # wrench matrix, C order
        self.WT = self.W.T  # (m, 6) view
        self.uT = self.W[:3]  # (3, m) unit vectors, base frame: B_i → exit point
        self._x9 = np.zeros((9, m))  # scratch of the stiffness computations
        self._pulley_idx = [int(i) for i in np.flatnonzero(model.pulley_radius > 0.0)]
        self._pulley_radius = [float(r) for r in model.pulley_radius]
        self._pulley_axis = [tuple(float(x) for x in a) for a in model.pulley_axis]
        self._anchor = [tuple(float(x) for x in a) for a in model.anchors]

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
    def cable_vectors(self) -> FloatArray:
        """(m, 3) m, base frame: ``B_i`` → exit point (view)."""
        return self.cable_vectorsT.T

    @property
    def attach_points(self) -> FloatArray:
        """(m, 3) m, base frame: the attachment points ``B_i = p + R b_i`` (allocates)."""
        return self.rb + self.position


def inverse_kinematics(
    model: RobotModel, data: KinematicsData, position: FloatArray, rotation: FloatArray
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
    r5, p5 = d._r5, d._p5
    r5[:3] = rotation
    r5[3:] = rotation[:2]
    p5[:3, 0] = position
    p5[3:] = p5[:2]
    rb5, v5 = d._rb5, d._v5
    np.dot(r5, d._bT, out=rb5)  # columns R b_i, cyclic row layout
    if d._pulley_idx:
        _pulley_exit_points(d)
    np.subtract(d._exit5, p5, out=v5)
    v5 -= rb5
    tmp = d._tmp
    np.multiply(d.cable_vectorsT, d.cable_vectorsT, out=tmp)
    np.add.reduce(tmp, axis=0, out=d.free_length)
    np.sqrt(d.free_length, out=d.free_length)
    inv_l = d._inv_l
    np.divide(1.0, d.free_length, out=inv_l)
    W = d.W
    np.multiply(d.cable_vectorsT, inv_l, out=W[:3])
    # Moment rows (R b_i) × u_i = ((R b_i) × v_i) / l_i, from the cyclic row blocks.
    mom = W[3:]
    np.multiply(rb5[1:4], v5[2:5], out=mom)
    np.multiply(rb5[2:5], v5[1:4], out=tmp)
    mom -= tmp
    mom *= inv_l
    if d._pulley_idx:
        np.multiply(d.wrap_angle, model.pulley_radius, out=d.length)
        d.length += d.free_length
    else:
        d.length[:] = d.free_length


def _pulley_exit_points(d: KinematicsData) -> None:
    """Tangent points and wrap angles of the swivel pulleys.

    In the pulley's plane (spanned by the swivel axis ``z`` and the radial direction ``e_r``
    towards ``B``), with the wheel centre ``C = a + r e_r`` as origin and ``B`` at
    ``(bx, bz)``: the cable enters at ``(−r, 0)`` travelling along ``+z``, wraps over the wheel
    and leaves at the tangent point of polar angle ``φ = atan2(bz, bx) + acos(r/|CB|)``; the
    wrapped arc is ``β = π − φ`` and the free length ``√(|CB|² − r²)``.
    (Swivel-pulley model of Pott, *Cable-Driven Parallel Robots*, Springer 2018, §2.5.)
    """
    px_, py_, pz_ = float(d._p5[0, 0]), float(d._p5[1, 0]), float(d._p5[2, 0])
    rb5, exit5 = d._rb5, d._exit5
    for i in d._pulley_idx:  # a few scalars per cable: plain floats beat numpy dispatch here
        r = d._pulley_radius[i]
        zx, zy, zz = d._pulley_axis[i]
        ax, ay, az = d._anchor[i]
        dx = px_ + float(rb5[0, i]) - ax
        dy = py_ + float(rb5[1, i]) - ay
        dz = pz_ + float(rb5[2, i]) - az
        along = dx * zx + dy * zy + dz * zz
        qx, qy, qz = dx - along * zx, dy - along * zy, dz - along * zz
        rho = math.sqrt(qx * qx + qy * qy + qz * qz)
        if rho > 1e-12:
            ex, ey, ez = qx / rho, qy / rho, qz / rho
        else:  # B on the swivel axis: the swivel angle is undefined, take any normal
            ex, ey, ez = _any_normal(np.array(d._pulley_axis[i]))
        bx, bz = rho - r, along
        dist = math.hypot(bx, bz)
        ratio = r / dist if dist > r else 1.0
        phi = math.atan2(bz, bx) + math.acos(ratio)
        c, s = r + r * math.cos(phi), r * math.sin(phi)
        tx, ty = ax + c * ex + s * zx, ay + c * ey + s * zy
        exit5[0, i] = tx
        exit5[1, i] = ty
        exit5[2, i] = az + c * ez + s * zz
        exit5[3, i] = tx
        exit5[4, i] = ty
        d.wrap_angle[i] = math.pi - phi


def _any_normal(axis: FloatArray) -> tuple[float, float, float]:
    ref = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    n = np.cross(axis, ref)
    n /= np.linalg.norm(n)
    return float(n[0]), float(n[1]), float(n[2])


def kinematics_ok(data: KinematicsData, min_length: float = 1e-6) -> bool:
    """True when every cable has a finite length above ``min_length`` (m)."""
    # min() propagates NaN and NaN > x is False: one reduction checks both.
    return bool(data.free_length.min() > min_length)


def cable_lengths(model: RobotModel, position: FloatArray, rotation: FloatArray) -> FloatArray:
    """Convenience (allocating) form: total cable lengths (m) at a pose."""
    data = KinematicsData(model)
    inverse_kinematics(model, data, position, rotation)
    return data.length.copy()


def wrench_matrix(model: RobotModel, position: FloatArray, rotation: FloatArray) -> FloatArray:
    """Convenience (allocating) form: the wrench matrix W (6×m) at a pose."""
    data = KinematicsData(model)
    inverse_kinematics(model, data, position, rotation)
    return np.array(data.W)
