"""Scalar rules written once for every layer: plain Python, each also compiled (``*_kernel``
names or the ``njit`` wrappers below) so that the kernels and the Python paths apply the same
text. Rotations are in ``rotation.py``.

* ``clamp``: a value within [lo, hi] (the torque limit of the drivers and the controller, the
  integral limit).
* ``plausible_step``: whether a motor can have turned by a step between two samples (the
  drivers' rejection of corrupted position feedback).
* ``forward_substitution``: a lower-triangular solve (forward kinematics, the null space).
* ``cable_compliance``: 1/k (m/N) of a cable and its series spring at a length (the model's
  stiffness, the estimator's stretch, the simulated plant's cable force).
* ``friction_law``, ``friction_regressors``, ``capstan_factor``: a winch's friction torque at a
  motor speed and a cable's loss over its pulley (the torque law and the tension estimate,
  the simulated plant's winches, ``cdprctl calibrate friction``'s fit).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numba import njit, types
from numba.core.errors import TypingError
from numba.core.typing import signature
from numba.extending import intrinsic
from numba.np.linalg import dot_3_mm, ensure_blas

#: A kernel the control loop calls from Python, which allocates nothing itself: compiled
#: without numba's reference counting, so that its array arguments are passed as they are —
#: with it, each one took a block from the allocator at every call (issue 64). A kernel that
#: builds an array (``np.eye``, ``@``) cannot be one: it does not compile so.
cycle_kernel = njit(cache=True, _nrt=False)  # type: ignore[call-overload]  # not in the stubs


def _matmul_into(typingctx, a, b, out):
    """``matmul_into(a, b, out)``: ``out`` ← ``a @ b`` in a kernel, the same BLAS call as
    numba's ``@`` (the same bits) into an existing array. ``np.dot(a, b, out)`` does the
    same but compiles only with reference counting, which a ``cycle_kernel`` is without.
    2-D float64; ``a``, ``b`` C- or F-contiguous (a transpose ``R.T`` is), ``out``
    C-contiguous. It uses numba's own lowering of that product (``numba.np.linalg``)."""
    arrays = (a, b, out)
    if not all(isinstance(x, types.Array) and x.ndim == 2 and x.dtype == types.float64
               for x in arrays):  # fmt: skip
        raise TypingError("matmul_into takes 2-D float64 arrays")
    if a.layout not in "CF" or b.layout not in "CF" or out.layout != "C":
        raise TypingError("matmul_into: a and b contiguous, out C-contiguous")

    def codegen(context, builder, sig, args):
        ensure_blas()
        dot_3_mm(context, builder, signature(sig.args[2], *sig.args), args)
        return context.get_dummy_value()

    return types.none(a, b, out), codegen


#: compiled calls only (``matmul_into(a, b, out)`` in a kernel; numba types it)
matmul_into: Any = intrinsic(_matmul_into)


@cycle_kernel
def count_kernel(counter, every):  # pragma: no cover - compiled
    """``counter[0]`` += 1; True when it is then a multiple of ``every``. A count kept in an
    int64 array: a Python int past 256 took a block at each increment."""
    counter[0] += 1
    return counter[0] % every == 0


@cycle_kernel
def add_count(counts, slot, n):  # pragma: no cover - compiled
    """``counts[slot]`` += ``n`` in place (an int64 array of counters: no int built)."""
    counts[slot] += n


def max2(a: float, b: float) -> float:
    """``max(a, b)`` exactly (ties and NaN alike: ``a`` unless ``b > a``), without the
    builtin's argument tuple (a block per call: the loop's Python code calls this)."""
    return b if b > a else a


def min2(a: float, b: float) -> float:
    """``min(a, b)`` exactly (``a`` unless ``b < a``), without the builtin's block."""
    return b if b < a else a


def _clamp(v: float, lo: float, hi: float) -> float:
    return min(hi, max(lo, v))


def _plausible_step(step: float, max_speed: float, elapsed: float, slack: float) -> bool:
    """A motor turning at most ``max_speed`` (rad/s) can move by ``step`` (rad) in the
    ``elapsed`` s since its last accepted sample plus ``slack`` s (a period, for timing
    jitter). A non-finite step is never plausible."""
    since = 0.0 if elapsed < 0.0 else elapsed  # max(elapsed, 0.0), without its block
    return abs(step) <= max_speed * (since + slack)


def _cable_compliance(
    inv_k_fixed: float, inv_es: float, l_winch: float, inv_spring: float, length: float
) -> float:
    """1/k (m/N) of a cable at ``length`` (m): a fixed stiffness ``1/k_fixed``, or the
    elastic ``(l + l_w)/(E S)`` (the cable from the exit point to the drum), plus the series
    spring's ``1/k_s`` (each term zero where it does not apply)."""
    return inv_k_fixed + inv_es * (length + l_winch) + inv_spring


@njit(cache=True)
def forward_substitution(L, b, y):  # pragma: no cover - compiled
    """``y`` ← the solution of ``L y = b`` for a lower-triangular ``L`` (n × n), row by row
    (the forward kinematics' Cholesky solve, the null space's ``Rᵀ y = w`` with ``L = Rᵀ``)."""
    for i in range(y.shape[0]):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]


#: rad/s: the smoothing of the Coulomb term's sign, ``tanh(θ̇/ω_ε)``, of the controller's law
FRICTION_SMOOTHING = 0.05
#: rad/s at the motor: the speed below which the Stribeck term (the breakaway friction beyond
#: the Coulomb level) acts, ``exp(−(θ̇/ω_s)²)``; a constant of the law, so that the law is
#: linear in its three coefficients (``friction_regressors``)
STRIBECK_SPEED = 2.0


def _friction_law(viscous: float, coulomb: float, stribeck: float, w: float,
                  smoothing: float) -> float:  # fmt: skip
    """N·m a winch's friction takes at motor speed ``w`` (rad/s): ``b θ̇ + (τ_c + τ_s
    exp(−(θ̇/ω_s)²)) tanh(θ̇/ω_ε)`` — viscous ``b`` (N·m·s/rad), Coulomb ``τ_c`` and Stribeck
    ``τ_s`` (N·m), ``ω_ε`` = ``smoothing`` (rad/s; Olsson et al., "Friction models and friction
    compensation", Eur. J. Control 1998, eq. (10) with a smooth sign)."""
    sign = math.tanh(w / smoothing)
    return viscous * w + (coulomb + stribeck * math.exp(-((w / STRIBECK_SPEED) ** 2))) * sign


def _capstan_factor(exponent: float, w: float, smoothing: float) -> float:
    """The winch-side tension over the platform-side one of a cable over its pulley: the
    capstan (Euler-Eytelwein) ``exp(±μ β)``, ``exponent`` = μ β (μ the coefficient, β rad the
    wrap), ``+`` winding in (θ̇ > 0: the winch pulls the cable over the pulley), ``−`` paying
    out, smoothed by ``tanh(θ̇/ω_ε)`` as the Coulomb term (``smoothing`` = ω_ε, rad/s)."""
    return math.exp(exponent * math.tanh(w / smoothing))


def friction_regressors(w: np.ndarray) -> np.ndarray:
    """(n, 3): the law's terms at motor speeds ``w`` (rad/s), per unit coefficient — viscous,
    Coulomb, Stribeck — so that ``friction_regressors(w) @ [b, τ_c, τ_s]`` is ``friction_law``
    at the controller's smoothing (the fit of ``cdprctl calibrate friction``)."""
    w = np.asarray(w, float)
    sign = np.tanh(w / FRICTION_SMOOTHING)
    return np.stack([w, sign, np.exp(-((w / STRIBECK_SPEED) ** 2)) * sign], axis=-1)


clamp = njit(cache=True)(_clamp)
friction_law = njit(cache=True)(_friction_law)
capstan_factor = njit(cache=True)(_capstan_factor)
plausible_step = njit(cache=True)(_plausible_step)
cable_compliance = njit(cache=True)(_cable_compliance)
#: the same rules for Python callers outside the loop (no compilation at import)
plausible_step_py = _plausible_step
cable_compliance_py = _cable_compliance


def compliance_terms(cable: object) -> tuple[float, float, float, float]:
    """``(1/k_fixed, 1/(E S), l_w, 1/k_s)`` of a ``Cable`` for ``cable_compliance``."""
    stiffness = getattr(cable, "stiffness", None)
    spring = getattr(cable, "spring_stiffness", None)
    if stiffness is not None:
        inv_k, inv_es = 1.0 / stiffness, 0.0
    else:
        es = (getattr(cable, "youngs_modulus", None) or 0.0) * (
            getattr(cable, "cross_section", None) or 0.0
        )
        inv_k, inv_es = 0.0, (1.0 / es if es > 0.0 else 0.0)
    return (
        inv_k,
        inv_es,
        float(getattr(cable, "length_to_winch", 0.0)),
        (1.0 / spring if spring else 0.0),
    )


def unstretched_lengths(law: Compliance, lengths: np.ndarray, tensions: np.ndarray) -> np.ndarray:
    """Each cable's unstretched length l0 (m) that, carrying ``tensions`` (N), spans the
    geometric ``lengths`` (m): the cable law ``l = l0 + t (1/k + (l0 + l_w)/(E S) + 1/k_s)``
    solved for l0 (exact: it is linear in l0)."""
    c0 = law.inv_k_fixed + law.inv_es * law.l_winch + law.inv_spring
    return (lengths - tensions * c0) / (1.0 + tensions * law.inv_es)


def kernel_args(bundle: tuple) -> tuple:
    """A bundle (a ``NamedTuple`` of arrays and numbers) as the kernels take it: a plain tuple
    of the same objects, which they unpack in the bundle's field order. numba matches a plain
    tuple's types in C; a named tuple's in Python, which doubled the estimator's call (8.7 →
    16.5 µs median in the lock-step loop on this VM)."""
    return tuple(kernel_args(x) if isinstance(x, tuple) else x for x in bundle)


class Compliance(NamedTuple):
    """The cable law's terms per cable (arrays, m/N, m/N per m, m, m/N); as kernel arguments
    (``kernel_args``), ``compliance_at(law, i, l)`` is cable ``i``'s 1/k at length ``l``."""

    inv_k_fixed: np.ndarray
    inv_es: np.ndarray
    l_winch: np.ndarray
    inv_spring: np.ndarray


def compliance_of(cables: Sequence[object]) -> Compliance:
    """The ``Compliance`` of a robot's ``Cable`` sequence (``compliance_terms``)."""
    terms = np.array([compliance_terms(c) for c in cables], dtype=float).reshape(len(cables), 4)
    return Compliance(*(np.ascontiguousarray(terms[:, j]) for j in range(4)))


@njit(cache=True)
def compliance_at(law, i, length):  # pragma: no cover - compiled
    """1/k (m/N) of cable ``i`` of ``law`` (a ``Compliance``) at ``length`` (m)."""
    inv_k_fixed, inv_es, l_winch, inv_spring = law
    return cable_compliance(inv_k_fixed[i], inv_es[i], l_winch[i], inv_spring[i], length)


@njit(cache=True)
def stiffness_kernel(lengths, law, out):  # pragma: no cover - compiled
    """``out`` ← the axial stiffness k_i (N/m) of each cable at ``lengths`` (m)."""
    for i in range(lengths.shape[0]):
        out[i] = 1.0 / compliance_at(law, i, lengths[i])


@cycle_kernel
def total(values):  # pragma: no cover - compiled
    """The sum, left to right from 0.0: Python 3.11's ``sum(values.tolist())`` of floats
    without the list and its floats (NaN and inf survive it: a finiteness check)."""
    s = 0.0
    for i in range(values.shape[0]):
        s += values[i]
    return s


@cycle_kernel
def largest(values):  # pragma: no cover - compiled
    """``max(values.tolist())`` without the list: the first greatest; a NaN is passed over
    unless it comes first, as by ``max``."""
    best = values[0]
    for i in range(1, values.shape[0]):
        if values[i] > best:
            best = values[i]
    return best


@cycle_kernel
def worst_ratio(values, limits):  # pragma: no cover - compiled
    """The index of the largest ``|values[i]| / limits[i]`` (limits > 0): the element nearest
    or furthest beyond its limit, without the arrays a numpy expression would build."""
    best, worst = -1.0, 0
    for i in range(values.shape[0]):
        ratio = abs(values[i]) / limits[i]
        if ratio > best:
            best, worst = ratio, i
    return worst
