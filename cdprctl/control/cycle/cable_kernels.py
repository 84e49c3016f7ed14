"""The compiled kernels of the fast loop in cable space (``cable_space.py`` says what each is
for and why): each winch's target, the catch-up after a stall, the integral force feedback,
the tension hold, the tensions the drives' torques measure, the internal part of their error
and the external-wrench estimate. Plain arrays in, results written into given arrays."""

from __future__ import annotations

import math

from cdprctl.control.cycle.tension_source import cable_tension
from cdprctl.control.cycle.torques import applied_tension
from cdprctl.core.numerics import compliance_at, cycle_kernel


@cycle_kernel
def motor_target_kernel(
    length, tensions, law, l_zero, drum_ratio, give, out
):  # pragma: no cover - compiled
    """``out`` (rad) ← each motor's angle that gives its cable the unstretched length which,
    stretched by ``tensions`` (N), spans its geometric ``length`` (m: at the reference pose,
    ``ReferencePose``), plus ``give`` (m, paid out: the force feedback's)."""
    for i in range(out.shape[0]):
        l0 = length[i]
        for _ in range(3):  # l0 = l − t c(l0): the compliance depends on l0 weakly
            l0 = length[i] - tensions[i] * compliance_at(law, i, l0)
        out[i] = (l_zero[i] - l0 - give[i]) / drum_ratio[i]


@cycle_kernel
def after_stall_kernel(
    target, sent, drive_rate, dev, dev_rate, dt, period, reach, late, tau
):  # pragma: no cover - compiled
    """``target`` (rad) ← the reference's targets plus the deviation ``dev`` (rad) the drives
    went into: after a ``late`` cycle where their interpolation went on at ``drive_rate``
    (rad/s) from ``sent`` for ``reach`` s (the stall, up to their extrapolation), else the
    last deviation taken back critically damped with time constant ``tau`` (s), its rate
    ``dev_rate`` (rad/s), over ``dt`` s: ``x(t) = (x₀ + B t) e^(−t/τ)``, ``B = v₀ + x₀/τ``.
    ``sent`` ← the targets; ``drive_rate`` ← the rate each drive takes to reach its target
    one ``period`` (s) after this SYNC, from where its interpolation stands at it."""
    decay = math.exp(-dt / tau)
    for i in range(target.shape[0]):
        if late:
            dev[i] = sent[i] + drive_rate[i] * reach - target[i]
            dev_rate[i] = 0.0
        else:
            b = dev_rate[i] + dev[i] / tau
            x = dev[i] + b * dt
            dev[i] = x * decay
            dev_rate[i] = (b - x / tau) * decay
        out = target[i] + dev[i]
        stands = sent[i] + drive_rate[i] * (reach - period)
        drive_rate[i] = (out - stands) / period
        sent[i] = out
        target[i] = out


@cycle_kernel
def force_feedback_kernel(error, k, decay, give):  # pragma: no cover - compiled
    """``give`` (m) per cable ← ``decay · give + (1 − decay) · error / k``: the cable paid out
    by the leaky integral of its tension ``error`` (N) over its stiffness ``k`` (N/m), gain =
    leak = β, ``decay = exp(−β dt)`` — the exact step, stable for any dt (forward Euler with
    β dt > 1 after a 100 ms stall flipped and grew: a 10.6 mm forward-kinematics residual
    fault in a 5-minute run at 500 Hz). Integral force feedback, Preumont: collocated, it
    damps every mode whose energy sits in the cables."""
    for i in range(give.shape[0]):
        give[i] = decay * give[i] + (1.0 - decay) * error[i] / k[i]


@cycle_kernel
def tension_hold_kernel(
    error, k, gain_dt, step_max, tension, slack, give
):  # pragma: no cover - compiled
    """``give`` (m) per cable ← ``give + gain_dt · min(error, 0) / k``, by at most ``step_max``
    (m): a cable carrying less than it should (``error`` N, measured − expected; ``k`` N/m)
    reeled in by the integral of its deficit, never paid out (a ratchet: it only takes back
    length a cable lost); not while its measured ``tension`` (N) is below ``slack`` (N):
    broken, or gone slack."""
    for i in range(give.shape[0]):
        if error[i] < 0.0 and tension[i] >= slack[i]:
            give[i] += max(gain_dt * error[i] / k[i], -step_max)


@cycle_kernel
def measured_tension_kernel(
    torque, velocity, sampled, winches, commanded, f_slow, f_fast, state, out, error, cells
):  # pragma: no cover - compiled  # fmt: skip
    """Per cable with a new sample (taken at ``sampled`` s, after ``last_sampled``): the
    tension its drive's measured ``torque`` (N·m) applies (``torques.applied_tension``), less
    the rotor's inertia ``J`` (kg·m²) at the acceleration its measured ``velocity`` (rad/s)
    shows since its last sample; ``out`` (N) ← a first-order low-pass at ``f_slow`` (Hz),
    stepped by the time between the samples, towards it. ``commanded_f`` the same low-pass
    of the ``commanded`` tensions (N); ``error`` (N) ← ``out − commanded_f``: what the cables
    carry beyond what was asked, both seen through the same filter; ``fast_error`` (N) the
    same difference through a low-pass at ``f_fast``, for the supervision.
    A torque beyond the drive's ``limit`` (N·m), or a rotor inertia term beyond twice it
    (motor and cable together cannot accelerate the rotor more), is a corrupted frame: that
    sample is skipped, the next one measured against the last good one. A cable's first
    sample only starts its count; a cable without a new one keeps its values.
    ``winches``: the ``WinchTerms`` (``r``, the friction, ``J``, the ``limit``); ``state``:
    ``(last_sampled, last_velocity, commanded_f, fast_error)``, updated in place. ``cells``
    (N per cable): the load cells' tensions, which replace the torque's where finite
    (``tension_source.cable_tension``)."""
    r, viscous, coulomb, stribeck, capstan, J, limit = winches
    last_sampled, last_velocity, commanded_f, fast_error = state
    for i in range(out.shape[0]):
        h = sampled[i] - last_sampled[i]
        if h > 0.0 and math.isfinite(h):
            rotor = J[i] * (velocity[i] - last_velocity[i]) / h
            t = cable_tension(
                applied_tension(torque[i], viscous[i], coulomb[i], stribeck[i], capstan[i],
                                velocity[i], rotor, r[i]),
                cells[i],
            )  # fmt: skip
            plausible = abs(torque[i]) <= 1.05 * limit[i] and abs(rotor) <= 2.0 * limit[i]
            if plausible and math.isfinite(t):
                alpha = 1.0 - math.exp(-2.0 * math.pi * f_slow * h)
                alpha_fast = 1.0 - math.exp(-2.0 * math.pi * f_fast * h)
                out[i] += alpha * (t - out[i])
                fast_error[i] += alpha_fast * (t - commanded[i] - fast_error[i])
                commanded_f[i] += alpha * (commanded[i] - commanded_f[i])
                last_sampled[i] = sampled[i]
                last_velocity[i] = velocity[i]
        elif not math.isfinite(last_sampled[i]) and math.isfinite(sampled[i] + velocity[i]):
            last_sampled[i] = sampled[i]
            last_velocity[i] = velocity[i]
        error[i] = out[i] - commanded_f[i]


@cycle_kernel
def internal_part_kernel(N, error, out, leverage):  # pragma: no cover - compiled
    """``out`` ← ``N Nᵀ error``: the part of the tension ``error`` (N) in the null space of W
    (``N`` an orthonormal basis, m × r): tensions the cables pull against each other with,
    which no external wrench on the platform explains (an external force changes the tensions
    along ``range(Wᵀ)``, by as much as the cables' stiffnesses are equal). ``leverage`` ←
    ``diag(N Nᵀ)``: the share of a cable's own error that shows there (for naming it)."""
    m, r = N.shape
    for i in range(m):
        out[i] = 0.0
        leverage[i] = 0.0
    for j in range(r):
        s = 0.0
        for i in range(m):
            s += N[i, j] * error[i]
            leverage[i] += N[i, j] * N[i, j]
        for i in range(m):
            out[i] += N[i, j] * s


@cycle_kernel
def disturbance_kernel(W, error, gain_dt, w_hat):  # pragma: no cover - compiled
    """``w_hat`` (6,) ← ``w_hat − gain_dt · W error``: the external wrench (N, N·m at P, base
    frame) as the integral of what the cables exert beyond what was commanded (``W error``:
    at rest it balances the part of the external wrench not yet fed forward, so the estimate
    converges to it as a first-order lag of rate ``gain_dt / dt``)."""
    for a in range(6):
        s = 0.0
        for i in range(error.shape[0]):
            s += W[a, i] * error[i]
        w_hat[a] -= gain_dt * s
