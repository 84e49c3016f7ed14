"""Rotation helpers.

Convention (used everywhere in cdprctl):

* Inside the code an orientation is a rotation matrix ``R`` (3×3) that maps vectors from the
  platform frame to the base frame: ``x_base = R @ x_platform``.
* At the boundaries (config files, CLI, commands) orientations are roll-pitch-yaw angles in
  radians, ``(roll, pitch, yaw)``, with ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``: rotations about the
  fixed base axes x, then y, then z (equivalently intrinsic z-y'-x''). This is the ROS/URDF
  convention and MATLAB's ``eul2rotm([yaw pitch roll])``.
* A small rotation is a rotation vector ``δφ`` (rad, base frame) applied on the left:
  ``R' = exp([δφ]×) @ R``. The stiffness matrix and the forward-kinematics Jacobian use it.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def rot_x(angle: float) -> FloatArray:
    """Rotation matrix about x by ``angle`` (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle: float) -> FloatArray:
    """Rotation matrix about y by ``angle`` (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle: float) -> FloatArray:
    """Rotation matrix about z by ``angle`` (rad)."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> FloatArray:
    """``R = Rz(yaw) Ry(pitch) Rx(roll)`` (angles in rad), platform → base."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(R: FloatArray) -> tuple[float, float, float]:
    """Inverse of :func:`rpy_to_matrix`; pitch in [-π/2, π/2], roll and yaw in (-π, π]."""
    pitch = math.asin(max(-1.0, min(1.0, -float(R[2, 0]))))
    if abs(math.cos(pitch)) > 1e-9:
        roll = math.atan2(float(R[2, 1]), float(R[2, 2]))
        yaw = math.atan2(float(R[1, 0]), float(R[0, 0]))
    else:  # gimbal lock: only roll ± yaw is defined; put it all in yaw
        roll = 0.0
        yaw = math.atan2(-float(R[0, 1]), float(R[1, 1]))
    return roll, pitch, yaw


def cross3(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a × b`` for 3-vectors: plain floats, ~1 µs against ~40-120 µs for ``np.cross`` (whose
    axis handling dominates at this size)."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def skew(v: FloatArray) -> FloatArray:
    """Cross-product matrix: ``skew(a) @ b == np.cross(a, b)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def rodrigues_into(x: float, y: float, z: float, out: FloatArray) -> None:
    """``out`` (3×3) ← ``exp([φ]×)`` of the rotation vector ``φ = (x, y, z)`` (rad), by
    Rodrigues' formula ``R = I + a K + b K²`` (``K = [φ]×``, ``K² = φφᵀ − θ² I``). The one
    rotation exponential of cdprctl: plain Python here, compiled as ``exp_so3_kernel`` for the
    kernels (forward kinematics, pose control, the simulated platform)."""
    angle2 = x * x + y * y + z * z
    if angle2 < 1e-16:  # Taylor expansion avoids 0/0: a = 1 − θ²/6, b = 1/2 − θ²/24
        a = 1.0 - angle2 / 6.0
        b = 0.5 - angle2 / 24.0
    else:
        angle = math.sqrt(angle2)
        a = math.sin(angle) / angle
        b = (1.0 - math.cos(angle)) / angle2
    out[0, 0] = 1.0 + b * (x * x - angle2)
    out[0, 1] = -a * z + b * x * y
    out[0, 2] = a * y + b * x * z
    out[1, 0] = a * z + b * x * y
    out[1, 1] = 1.0 + b * (y * y - angle2)
    out[1, 2] = -a * x + b * y * z
    out[2, 0] = -a * y + b * x * z
    out[2, 1] = a * x + b * y * z
    out[2, 2] = 1.0 + b * (z * z - angle2)


exp_so3_kernel = njit(cache=True)(rodrigues_into)


def exp_so3(phi: FloatArray) -> FloatArray:
    """Rotation matrix of the rotation vector ``phi`` (rad) (:func:`rodrigues_into`)."""
    out = np.empty((3, 3))
    rodrigues_into(float(phi[0]), float(phi[1]), float(phi[2]), out)
    return out


def log_so3_into(R: FloatArray, out: FloatArray) -> None:
    """``out[0:3]`` ← the rotation vector (rad) of the rotation matrix ``R`` (inverse of
    :func:`rodrigues_into`). The one rotation logarithm: plain Python here, compiled as
    ``log_so3_kernel``."""
    c = (R[0, 0] + R[1, 1] + R[2, 2] - 1.0) / 2.0
    c = max(-1.0, min(1.0, c))
    angle = math.acos(c)
    wx = R[2, 1] - R[1, 2]
    wy = R[0, 2] - R[2, 0]
    wz = R[1, 0] - R[0, 1]
    if angle < 1e-8:
        out[0] = 0.5 * wx
        out[1] = 0.5 * wy
        out[2] = 0.5 * wz
    elif math.pi - angle < 1e-6:  # near π: the axis from the symmetric part
        k = 0
        for i in range(1, 3):
            if R[i, i] > R[k, k]:
                k = i
        mkk = max((R[k, k] + 1.0) / 2.0, 1e-300)
        s = math.sqrt(mkk)
        for i in range(3):
            m_ik = (R[i, k] + R[k, i]) / 4.0 + (0.5 if i == k else 0.0)
            out[i] = angle * m_ik / s
    else:
        f = angle / (2.0 * math.sin(angle))
        out[0] = f * wx
        out[1] = f * wy
        out[2] = f * wz


log_so3_kernel = njit(cache=True)(log_so3_into)


@njit(cache=True)
def rotated_kernel(phi, R_base, E, out):  # pragma: no cover - compiled
    """``out`` (3×3) ← ``exp([φ]×) R_base``: the rotation vector ``phi`` (rad, base frame)
    applied to ``R_base`` — a pose's rotation from its coordinates about the home rotation.
    ``E``: (3, 3) scratch."""
    exp_so3_kernel(phi[0], phi[1], phi[2], E)
    for i in range(3):
        for j in range(3):
            out[i, j] = E[i, 0] * R_base[0, j] + E[i, 1] * R_base[1, j] + E[i, 2] * R_base[2, j]


@njit(cache=True)
def log_relative_kernel(A, B, E, out):  # pragma: no cover - compiled
    """``out[0:3]`` ← ``log(A Bᵀ)``: the rotation vector (rad, base frame) that takes ``B`` to
    ``A`` — an orientation error. ``E``: (3, 3) scratch."""
    for i in range(3):
        for j in range(3):
            E[i, j] = A[i, 0] * B[j, 0] + A[i, 1] * B[j, 1] + A[i, 2] * B[j, 2]
    log_so3_kernel(E, out)


def log_so3(R: FloatArray) -> FloatArray:
    """Rotation vector (rad) of the rotation matrix ``R`` (:func:`log_so3_into`)."""
    out = np.empty(3)
    log_so3_into(np.asarray(R, dtype=float), out)
    return out
