"""The fit of ``cdprctl calibrate friction`` (docs/friction.md): each winch's friction from its
drive's torque while the platform goes out and back along the same line at several speeds.

Per winch, every cycle ``k`` of the moves: ``τ_k = g(s_k) + f(θ̇_k) + J θ̈_k [+ μ β g(s_k)
tanh(θ̇_k/ω_ε)] + r N λ_k`` — ``s`` the fraction of the line where the platform is, ``g`` the
statics
(the cable's tension times r, and whatever else depends on the pose alone: a Legendre series
in ``s`` the fit takes as it comes, so that the statics cancel between the ways out and back),
``f`` the friction law (``numerics.friction_regressors``: viscous, Coulomb, Stribeck), ``J``
the inertia the drive accelerates, and the pulley's capstan loss to first order
(``exp(±μβ) ≈ 1 ± μβ``, the winch-side tension times it, read from the torque); ``λ_k`` the
internal
tensions (the null space ``N`` of the wrench matrix), whatever the drives' loops make them:
every winch's equation is taken together, projected off them (``null_projectors``). Linear
least squares; each parameter's standard deviation from the residuals' variance,
``σ² (XᵀX)⁻¹`` (the samples' noise taken as independent: an optimistic σ).

The pulley's μ is fitted only where the cable wraps a pulley, and kept only where the data
decide it: its term differs from the Coulomb one by the tension's change along the line, and
a line along which the tension hardly changes leaves the two apart by less than the noise
(its σ beyond ``PULLEY_DECIDED`` of its value, or of ``PULLEY_FLOOR``): then μ is the file's
and the fit says so.

The residual check: a fit is refused when its residuals' RMS exceeds ``RESIDUAL_FACTOR``
times the torque's noise at rest (plus one torque count): friction the law does not explain
(a binding bearing, a cable rubbing, a slipping drum) leaves a residual of its own size."""

from __future__ import annotations

import dataclasses

import numpy as np

from cdprctl.core.numerics import FRICTION_SMOOTHING, friction_regressors

#: the statics' Legendre series in the line's fraction: degree (12: the tension along 0.3-0.6 m
#: of rowc's and CoGiRo's lines to within the torque's resolution)
STATICS_DEGREE = 12
#: a fit whose residual RMS is beyond this times the torque's noise is refused
RESIDUAL_FACTOR = 2.0
#: μ kept only when its σ is within this fraction of max(μ, ``PULLEY_FLOOR``)
PULLEY_DECIDED = 0.2
PULLEY_FLOOR = 0.02


@dataclasses.dataclass
class WinchFriction:
    """One winch's identified terms with their standard deviations: ``viscous`` N·m·s/rad,
    ``coulomb`` and ``stribeck`` N·m, ``inertia`` kg·m² (at the motor), the pulley's ``pulley``
    μ (None: not decided by the data, or no pulley), the residual's RMS and its limit (N·m)."""

    viscous: float
    coulomb: float
    stribeck: float
    inertia: float
    std: tuple[float, float, float, float]
    pulley: float | None
    pulley_std: float | None
    residual_rms: float
    residual_limit: float
    samples: int
    pulley_note: str = ""
    source: str = "torques"  # "load cell": the cable's tension measured (``fit_measured``)

    @property
    def explained(self) -> bool:
        return self.residual_rms <= self.residual_limit


def statics_basis(s: np.ndarray) -> np.ndarray:
    """(n, STATICS_DEGREE + 1): Legendre polynomials of ``2 s − 1`` (``s`` in [0, 1])."""
    return np.polynomial.legendre.legvander(2.0 * np.asarray(s, float) - 1.0, STATICS_DEGREE)


def line_statics(s: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(n, lines × d): each sample's statics series in the block of its ``line`` (0, 1, ...):
    the statics of each line are their own function of the fraction ``s``."""
    d = STATICS_DEGREE + 1
    lines = int(np.max(line)) + 1
    out = np.zeros((len(s), lines * d))
    basis = statics_basis(s)
    for j in range(lines):
        on = line == j
        out[on, j * d : (j + 1) * d] = basis[on]
    return out


def _design(statics: np.ndarray, speed: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
    """(n, m, p): per sample and winch the terms of its torque, per unit coefficient: the
    statics' series (``line_statics``), the friction law's three terms, the acceleration."""
    n, m = speed.shape
    fr = friction_regressors(speed)  # (n, m, 3)
    return np.concatenate(
        [np.broadcast_to(statics[:, None, :], (n, m, statics.shape[1])), fr,
         acceleration[:, :, None]], axis=2)  # fmt: skip


def _solve(Q: np.ndarray, Y: np.ndarray, torque: np.ndarray) -> tuple[np.ndarray, ...]:
    """Least squares of ``Q_k τ_k = Q_k Y_k c`` over the samples ``k`` (``c``: every winch's
    coefficients, (m, p)); normal equations accumulated, columns scaled to unit norm.
    Returns the coefficients (m, p), their covariance ((m p)², from the residuals' variance
    over the rows' degrees of freedom) and the residuals (n, m)."""
    n, m, p = Y.shape
    A = np.zeros((m, p, m, p))
    b = np.zeros((m, p))
    for k0 in range(0, n, 2000):
        q, y, t = Q[k0 : k0 + 2000], Y[k0 : k0 + 2000], torque[k0 : k0 + 2000]
        A += np.einsum("kij,kia,kjb->iajb", q, y, y, optimize=True)
        b += np.einsum("kij,kia,kj->ia", q, y, t, optimize=True)
    A2, b1 = A.reshape(m * p, m * p), b.ravel()
    scale = np.sqrt(np.maximum(np.diag(A2), 1e-300))
    As = A2 / np.outer(scale, scale)
    inv = np.linalg.pinv(As, rcond=1e-12, hermitian=True)
    coef = inv @ (b1 / scale) / scale
    c = coef.reshape(m, p)
    res = np.einsum("kij,kj->ki", Q, torque - np.einsum("kia,ia->ki", Y, c))
    rank = np.linalg.matrix_rank(As, tol=1e-12 * np.max(np.linalg.eigvalsh(As)), hermitian=True)
    dof = max(1, round(float(np.trace(Q[0]))) * n - int(rank))
    cov = (float(np.sum(res**2)) / dof) * inv / np.outer(scale, scale)
    return c, cov, res


def null_projectors(W: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(n, m, m): for each wrench matrix ``W`` (n, 6, m) the projector that takes out of a
    vector of motor torques the directions the cables' internal tensions move it in
    (``diag(r) N``, ``N`` the null space of W, ``r`` m/rad): the torques with every internal
    tension the drives' lags leave taken out (a robot with more than six cables all held by
    position: rowc's stiff cables pulled against each other by up to 300 N along a line,
    their odd part a third of its Coulomb friction)."""
    m = W.shape[2]
    _, sv, vt = np.linalg.svd(W)  # batched: (n, 6), (n, m, m)
    rank = int(np.min(np.sum(sv > 1e-9 * sv[:, :1], axis=1)))
    B = r[None, :, None] * np.swapaxes(vt[:, rank:, :], 1, 2)  # (n, m, m - rank)
    # B's columns orthonormalised: Q = I − U Uᵀ
    U, _ = np.linalg.qr(B)
    return np.eye(m)[None] - U @ np.swapaxes(U, 1, 2)


def pulley_decided(mu: float, sd: float) -> bool:
    """Whether the data decide a pulley's μ fitted as ``mu`` ± ``sd``: its σ within
    ``PULLEY_DECIDED`` of it (of ``PULLEY_FLOOR`` where it is smaller)."""
    return sd <= PULLEY_DECIDED * max(abs(mu), PULLEY_FLOOR)


def fit_winches(s: np.ndarray, line: np.ndarray, Q: np.ndarray, speed: np.ndarray,
                acceleration: np.ndarray, torque: np.ndarray, noise: np.ndarray,
                wrap: np.ndarray) -> list[WinchFriction]:  # fmt: skip
    """Every winch's friction from the samples: the ``line`` each is on (0, 1, ...) and the
    fraction ``s`` of it (n), the
    projectors ``Q`` (n, m, m; ``null_projectors``), the motor ``speed`` (rad/s),
    ``acceleration`` (rad/s²) and ``torque`` (N·m), each (n, m); ``noise`` (N·m, per winch)
    the torque's σ at rest with one count (the residual's limit); ``wrap`` (rad, (n, m)) each
    cable's wrap on its pulley at each sample (0: none, no μ fitted)."""
    statics = line_statics(s, line)
    Y = _design(statics, speed, acceleration)
    c, cov, res = _solve(Q, Y, torque)
    n, m, p = (int(x) for x in Y.shape)
    d = statics.shape[1]
    pulley: list[float | None] = [None] * m
    pulley_std: list[float | None] = [None] * m
    pulleys = np.max(wrap, axis=0) > 0.0
    notes = ["" if pulleys[i] else "no pulley" for i in range(m)]
    if np.any(pulleys):
        # r t on the winch's side: the measured torque itself (the friction in it changes the
        # term by μβ of itself: second order). Not the fitted statics: projected, they are
        # known only up to the internal tensions' directions
        col = wrap * torque * np.tanh(speed / FRICTION_SMOOTHING)
        Yp = np.concatenate([Y, col[:, :, None]], axis=2)  # μ's column last
        cp, covp, resp = _solve(Q, Yp, torque)
        decided = []
        for i in (int(x) for x in np.flatnonzero(pulleys)):
            mu, sd = float(cp[i, -1]), float(np.sqrt(covp[i * (p + 1) + p, i * (p + 1) + p]))
            if pulley_decided(mu, sd):
                decided.append(i)
                pulley[i], pulley_std[i] = mu, sd
            else:
                notes[i] = (f"not decided by the data: μ = {mu:.3f} ± {sd:.3f} (the tension "
                            "changes too little along the line to tell it from the Coulomb "
                            "term)")  # fmt: skip
        if decided:
            c, res, p = cp, resp, p + 1
            cov = covp
            for other in set(range(m)) - set(decided):
                c[other, -1] = 0.0
    fits = []
    for i in range(m):
        k = [i * p + d + j for j in range(4)]
        std = np.sqrt(np.maximum(np.diag(cov)[k], 0.0))
        fits.append(WinchFriction(
            viscous=float(c[i, d]), coulomb=float(c[i, d + 1]), stribeck=float(c[i, d + 2]),
            inertia=float(c[i, d + 3]), std=(float(std[0]), float(std[1]), float(std[2]),
                                            float(std[3])),
            pulley=pulley[i], pulley_std=pulley_std[i],
            residual_rms=float(np.sqrt(np.mean(res[:, i] ** 2))),
            residual_limit=RESIDUAL_FACTOR * float(noise[i]), samples=n, pulley_note=notes[i],
        ))  # fmt: skip
    return fits


def fit_measured(s: np.ndarray, line: np.ndarray, speed: np.ndarray, acceleration: np.ndarray,
                 torque: np.ndarray, load: np.ndarray, load_rate: np.ndarray, noise: float,
                 wrap: np.ndarray) -> WinchFriction:  # fmt: skip
    """One winch's friction where its cable's tension is measured (a load cell): its drive's
    ``torque`` less ``load`` (both N·m, n: ``r`` × the cell's tension at each sample) is the
    friction and the rotor's inertia alone (``τ − r t = f(θ̇) + J θ̈``), fitted winch by
    winch: no internal tensions to take out, so no projection. Beside the law:

    * a statics series per line (``line_statics``): what depends on the pose alone, a cell's
      offset or its scale error on the tension's even part;
    * ``load_rate`` (N·m/s, the rate of ``load``) times a fitted time ``δ`` (s): the drive
      holds its torque's feed-forward over a period while the tension goes on changing, and
      its loop's catching up leaves the rotor accelerating early in the period and slowing
      late (measured in the simulated robot, every physics step: ∓0.1 rad/s² per rad/s of
      speed at the period's end on rowc), an inertial torque at the sample's instant that
      the period's mean acceleration does not carry; it goes with the tension's rate, which
      is odd in the motion as the viscous term is (rowc: 5-8 % off without it, δ ≈ −2 ms).

    ``speed``, ``acceleration``: the motor's (rad/s, rad/s², n); ``noise`` the torque's σ at
    rest (N·m, the residual's limit); ``wrap`` the cable's wrap on its pulley (rad, n; 0:
    none): with a pulley, its μ from the capstan's first-order term ``r t β tanh(θ̇/ω_ε)``
    (the cell on the platform's side), kept as ``fit_winches`` keeps it."""
    net = torque - load
    X = np.concatenate([line_statics(s, line), friction_regressors(speed),
                        acceleration[:, None], load_rate[:, None]], axis=1)  # fmt: skip
    d, wrapped = X.shape[1] - 5, bool(np.max(wrap) > 0.0)
    if wrapped:
        X = np.c_[X, wrap * load * np.tanh(speed / FRICTION_SMOOTHING)]
    scale = np.maximum(np.linalg.norm(X, axis=0), 1e-300)
    inv = np.linalg.pinv((X / scale).T @ (X / scale), rcond=1e-12, hermitian=True)
    c = inv @ ((X / scale).T @ net) / scale
    res = net - X @ c
    rank = int(np.linalg.matrix_rank(X / scale))
    cov = float(res @ res) / max(1, len(net) - rank) * inv / np.outer(scale, scale)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    pulley, pulley_sd, note = None, None, "" if wrapped else "no pulley"
    if wrapped:
        mu, mu_sd = float(c[-1]), float(sd[-1])
        if pulley_decided(mu, mu_sd):
            pulley, pulley_sd = mu, mu_sd
        else:
            note = f"not decided by the data: μ = {mu:.3f} ± {mu_sd:.3f}"
    return WinchFriction(
        viscous=float(c[d]), coulomb=float(c[d + 1]), stribeck=float(c[d + 2]),
        inertia=float(c[d + 3]), std=(float(sd[d]), float(sd[d + 1]), float(sd[d + 2]),
                                      float(sd[d + 3])),
        pulley=pulley, pulley_std=pulley_sd, residual_rms=float(np.sqrt(np.mean(res**2))),
        residual_limit=RESIDUAL_FACTOR * float(noise), samples=len(net), pulley_note=note,
        source="load cell")  # fmt: skip


def refusal(names: list[str], fits: list[WinchFriction]) -> str:
    """Why the fits are refused ("" when every winch's is accepted): the winch whose residual
    the law explains least, beyond its limit (the winches' equations are solved together:
    a bearing's residual spreads a little to the others), or whose terms come out negative
    (beyond 3 σ)."""
    worst = max(range(len(fits)), key=lambda i: fits[i].residual_rms / fits[i].residual_limit)
    for name, f in ((names[worst], fits[worst]), *zip(names, fits, strict=True)):
        if not f.explained:
            return (f"winch {name}: the residual RMS {f.residual_rms:.4f} N·m exceeds its "
                    f"limit {f.residual_limit:.4f} N·m ({RESIDUAL_FACTOR:g}x the torque's "
                    "noise at rest): friction the law does not explain (a binding bearing, "
                    "a cable rubbing, a drum slipping)")  # fmt: skip
        for what, x, sd in (("viscous", f.viscous, f.std[0]), ("Coulomb", f.coulomb, f.std[1])):
            if x < -3.0 * sd:
                return (f"winch {name}: the {what} term came out {x:.3g} ± {sd:.2g}, "
                        "negative: the drive's torque is not the law's")  # fmt: skip
    return ""
