"""The ODrive driver's cyclic path, compiled (``numerics.cycle_kernel``: no block per cycle,
issue 64): the cyclic frames packed into their bytes, and the following error's supervision.
The rules as ``driver.py`` states them (``_following``); here they take no Python int or
numpy scalar per value."""

from __future__ import annotations

import math

import numpy as np

from cdprctl.core.numerics import cycle_kernel
from drivers.odrive import protocol as p

TWO_PI = 2.0 * math.pi
_VEL_FF_SCALE, _TORQUE_FF_SCALE = p.VEL_FF_SCALE, p.TORQUE_FF_SCALE
_INT16_MAX = float(p.INT16_MAX)


@cycle_kernel
def _float32_into(x, f32, f32_bytes, d):  # pragma: no cover - compiled
    """``d[0:4]`` ← ``x`` as a little-endian float32 (``f32``, ``f32_bytes``: one float32
    and its bytes, a scratch), as ``struct``'s ``<f`` packs it."""
    f32[0] = x
    for k in range(4):
        d[k] = f32_bytes[k]


@cycle_kernel
def _int16_into(v, d, k):  # pragma: no cover - compiled
    """``d[k:k + 2]`` ← ``v`` (within ±32767) as a little-endian int16 (``<h``)."""
    n = np.int64(v)
    d[k], d[k + 1] = n & 0xFF, (n >> 8) & 0xFF


@cycle_kernel
def pack_frames_kernel(
    targets, torques, csp, period, sent_target, hold_from, path_from, frames, f32, f32_bytes
):  # pragma: no cover - compiled
    """Each axis's cyclic frame (``frames[c]``: its bytes): in position mode (``csp[c]``)
    Set_Input_Pos — the middle of the last target and this one (rad → turns, float32), the
    target's rate over the ``period`` (s) as the velocity feed-forward and the torque (N·m)
    as the torque feed-forward (int16 counts of ``VEL_FF_SCALE`` and ``TORQUE_FF_SCALE``,
    each rounded half to even like Python's ``round`` and saturated) — the targets' history
    (``sent_target``, ``hold_from``, ``path_from``, rad) moved on; else Set_Input_Torque
    (float32 N·m). Returns how many velocity feed-forwards were saturated."""
    clamped = 0
    for c in range(targets.shape[0]):
        d = frames[c]
        if not csp[c]:
            _float32_into(torques[c], f32, f32_bytes, d)
            continue
        target, last = targets[c], sent_target[c]
        rate = np.rint((target - last) / (TWO_PI * period * _VEL_FF_SCALE))
        vel = max(-_INT16_MAX, min(_INT16_MAX, rate))
        if vel != rate:
            clamped += 1
        tau = max(-_INT16_MAX, min(_INT16_MAX, np.rint(torques[c] / _TORQUE_FF_SCALE)))
        _float32_into(0.5 * (last + target) / TWO_PI, f32, f32_bytes, d)
        _int16_into(vel, d, 4)
        _int16_into(tau, d, 6)
        path_from[c] = hold_from[c]
        hold_from[c] = last
        sent_target[c] = target
    return clamped


@cycle_kernel
def following_kernel(
    csp, closed, path_from, hold_from, sent_target, position, window, beyond, following,
    off_at, dt, timeout,
):  # pragma: no cover - compiled  # fmt: skip
    """Each axis in position mode (``csp``) and closed loop (``closed``) off the path of its
    last two holds (``path_from``, ``hold_from``, ``sent_target``, rad) by more than its
    ``window`` (rad):
    ``beyond`` (s) grows by ``dt``; past ``timeout`` (s) it latches ``following`` and the
    distance into ``off_at`` (rad). Within the window, or off: ``beyond`` back to zero."""
    for c in range(position.shape[0]):
        a, b, e = path_from[c], hold_from[c], sent_target[c]
        x = position[c]
        off = max(min(a, b, e) - x, x - max(a, b, e))
        if csp[c] and closed[c] and off > window[c]:
            beyond[c] += dt
            if beyond[c] > timeout and not following[c]:
                following[c] = True
                off_at[c] = off
        else:
            beyond[c] = 0.0
