"""The command's edge, compiled: each cycle's torques clamped to the winches' limits (a
non-finite one replaced by the last valid command) and the position targets taken where they
are finite (``drivers/base.py``, ``WinchDriver.write``)."""

from __future__ import annotations

import numpy as np

from cdprctl.core.numerics import clamp, cycle_kernel


@cycle_kernel
def clamp_kernel(torques, last, limit, out):  # pragma: no cover - compiled
    """``out`` ← ``torques`` (N·m) within ±``limit``, a non-finite one replaced by ``last``
    (the last valid command); returns the counts of replaced and clamped commands."""
    rejected = 0
    clamped = 0
    for i in range(len(out)):
        v = torques[i]
        if not np.isfinite(v):
            rejected += 1
            v = last[i]
        out[i] = clamp(v, -limit[i], limit[i])
        if out[i] != v:
            clamped += 1
    return rejected, clamped


@cycle_kernel
def finite_into(values, out):  # pragma: no cover - compiled
    """``out[i]`` ← ``values[i]`` where it is finite; the others keep their last value."""
    for i in range(len(out)):
        if np.isfinite(values[i]):
            out[i] = values[i]
