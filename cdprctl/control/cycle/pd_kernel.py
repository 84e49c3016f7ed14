"""The PID + feed-forward wrench of one control cycle, compiled (numba).

Same law as documented in ``controller.py`` (``M (a_d + kp e + ki ∫e + kd ė) − w_g − w_e``);
in plain numpy it cost ~120 µs a cycle on this VM, all of it per-call overhead on 3-vectors.
tests/control/cycle/test_pd_kernel.py checks it against a numpy transcription of the law.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cdprctl.core.numerics import cycle_kernel
from cdprctl.core.rotation import log_relative_kernel, rotated_kernel


class Reference(NamedTuple):
    """The trajectory now: position and rotation vector from home (m, rad), their rates
    (m/s, rad/s) and accelerations (m/s², rad/s²), each (6,)."""

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray


class PoseEstimate(NamedTuple):
    """The estimate: P (m, base frame), orientation (3, 3), velocity (m/s), ω (rad/s, base)."""

    p: np.ndarray
    R: np.ndarray
    v: np.ndarray
    w: np.ndarray


class Pid(NamedTuple):
    """Per axis (x, y, z, roll, pitch, yaw): kp (1/s²), kd (1/s), ki (1/s³), the integral
    (m·s, rad·s; updated in place) and its limit."""

    kp: np.ndarray
    kd: np.ndarray
    ki: np.ndarray
    integral: np.ndarray
    integral_limit: np.ndarray


class Platform(NamedTuple):
    """Home orientation (3, 3), mass (kg), inertia (kg·m², platform frame, about the COM),
    COM (m, platform frame), gravity (m/s², base frame)."""

    R_home: np.ndarray
    mass: float
    inertia: np.ndarray
    com: np.ndarray
    gravity: np.ndarray


@cycle_kernel
def pd_wrench_kernel(
    ref, est, pid, integrate, dt, platform, ext_wrench, Rd, E, S, err, wrench, feedback
):  # pragma: no cover - compiled
    """``err`` (6,) ← reference − estimate; ``wrench`` (6,) ← what the cables must exert (N,
    N·m at P, base frame), the known ``ext_wrench`` fed forward; ``feedback`` (6,) ← the part
    of ``wrench`` the PID adds to the feed-forward (``M (kp e + ki ∫e + kd ė)``: what a
    saturation may scale, the rest must be held); the integral grows by ``err dt`` when
    ``integrate``. ``Rd``, ``E``: (3, 3) scratch; ``S`` (15,): scratch, the vectors (none is
    built in the loop)."""
    ref_x, ref_v, ref_a = ref
    p, R, v, w = est
    kp, kd, ki, integral, integral_limit = pid
    R_home, mass, inertia, com, gravity = platform
    rotated_kernel(ref_x[3:], R_home, E, Rd)
    for i in range(3):
        err[i] = ref_x[i] - p[i]
    log_relative_kernel(Rd, R, E, err[3:])
    if integrate:
        for i in range(6):
            lim = integral_limit[i]
            integral[i] = min(lim, max(-lim, integral[i] + err[i] * dt))
    acc, Iwa, Iww, r = S[:6], S[6:9], S[9:12], S[12:15]
    for i in range(3):
        j = 3 + i
        acc[i] = ref_a[i] + kp[i] * err[i] + ki[i] * integral[i] + kd[i] * (ref_v[i] - v[i])
        acc[j] = ref_a[j] + kp[j] * err[j] + ki[j] * integral[j] + kd[j] * (ref_v[j] - w[i])
    # Iw = R I Rᵀ (base frame), into E
    for i in range(3):
        for j in range(3):
            s = 0.0
            for k in range(3):
                for m in range(3):
                    s += R[i, k] * inertia[k, m] * R[j, m]
            E[i, j] = s
    for i in range(3):
        Iwa[i] = E[i, 0] * acc[3] + E[i, 1] * acc[4] + E[i, 2] * acc[5]
        Iww[i] = E[i, 0] * w[0] + E[i, 1] * w[1] + E[i, 2] * w[2]
    # gravity: f = m g at the COM r = R com; the cables hold −(w_g + w_e)
    for i in range(3):
        r[i] = R[i, 0] * com[0] + R[i, 1] * com[1] + R[i, 2] * com[2]
    f0, f1, f2 = mass * gravity[0], mass * gravity[1], mass * gravity[2]
    wrench[0] = mass * acc[0] - f0 - ext_wrench[0]
    wrench[1] = mass * acc[1] - f1 - ext_wrench[1]
    wrench[2] = mass * acc[2] - f2 - ext_wrench[2]
    wrench[3] = Iwa[0] + (w[1] * Iww[2] - w[2] * Iww[1]) - (r[1] * f2 - r[2] * f1) - ext_wrench[3]
    wrench[4] = Iwa[1] + (w[2] * Iww[0] - w[0] * Iww[2]) - (r[2] * f0 - r[0] * f2) - ext_wrench[4]
    wrench[5] = Iwa[2] + (w[0] * Iww[1] - w[1] * Iww[0]) - (r[0] * f1 - r[1] * f0) - ext_wrench[5]
    for i in range(3):
        feedback[i] = mass * (acc[i] - ref_a[i])
        s = 0.0
        for j in range(3):
            s += E[i, j] * (acc[3 + j] - ref_a[3 + j])
        feedback[3 + i] = s
