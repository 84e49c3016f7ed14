"""Tensions to winch motor torques, compiled (one call instead of ~12 numpy operations, ~20 µs
a cycle on this VM)."""

from __future__ import annotations

import math

from numba import njit

#: rad/s: the Coulomb friction model's ``tanh(θ̇/ω_ε)`` smoothing of the sign
FRICTION_SMOOTHING = 0.05


@njit(cache=True)
def winch_torque_kernel(
    tensions, r, viscous, coulomb, rotor_inertia, WT, acceleration, velocity, friction, limit, out
):  # pragma: no cover - compiled
    """``out`` ← ``τ = r t + b θ̇ + τ_c tanh(θ̇/ω_ε) + J θ̈_d`` (N·m) within ±``limit``.

    ``r`` (m/rad) the drum radius over the gear ratio, ``t`` (N) the tensions, ``θ̇``
    (rad/s) the motor velocities, friction terms only when ``friction``; the rotor's
    ``θ̈_d = Wᵀ a_d / r`` from the desired platform acceleration ``a_d`` (``δl = −Wᵀ δX`` and
    ``l0 = l − r θ``: θ > 0 winds in).
    """
    for i in range(out.shape[0]):
        tau = r[i] * tensions[i]
        if friction:
            w = velocity[i]
            tau += viscous[i] * w + coulomb[i] * math.tanh(w / FRICTION_SMOOTHING)
        acc = 0.0
        for a in range(6):
            acc += WT[i, a] * acceleration[a]
        tau += rotor_inertia[i] * acc / r[i]
        out[i] = min(limit[i], max(-limit[i], tau))
