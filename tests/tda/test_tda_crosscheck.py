"""Tension distribution against independent references: brute-force polygons, scipy's LP
(HiGHS), quadprog in tension space, and invariants that must hold for any input."""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np
import pytest
import quadprog
from conftest import CONFIG, random_poses
from scipy.optimize import linprog

from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.robot_file import load_robot
from cdprctl.tda import TDAMethod, TDAOptions, TDAStatus, TensionDistributor
from cdprctl.tda.nullspace import NullSpace
from cdprctl.tda.polygon import area_centroid, feasible_polygon, least_violating

ROBOTS = ["rowc.toml", "seed000.toml", "caroca.toml", "cogiro.toml"]


def cases(model, n, seed, near_limit=False, infeasible=False):
    """(W, w, lo, hi): wrenches made from random tensions, so feasible unless ``infeasible``."""
    rng = np.random.default_rng(seed)
    lo, hi = model.tension_min, model.tension_max
    d = KinematicsData(model)
    for p, R in random_poses(model, n, rng, tilt=0.1):
        inverse_kinematics(model, d, p, R)
        t = rng.uniform(lo, hi)
        if near_limit:  # two cables exactly at a bound: a thin or degenerate polygon
            i, j = rng.choice(model.n_cables, 2, replace=False)
            t[i], t[j] = lo[i], hi[j]
        if infeasible:
            t = t + rng.choice([-1.0, 1.0], model.n_cables) * rng.uniform(0.1, 0.6) * (hi - lo)
        yield d.W.copy(), d.W @ t, lo, hi


def lp_feasible(W, w, lo, hi, c=None):
    m = W.shape[1]
    res = linprog(
        np.zeros(m) if c is None else c,
        A_eq=W,
        b_eq=w,
        bounds=list(zip(lo, hi, strict=True)),
        method="highs",
    )
    return res


def brute_force_vertices(N, t0, lo, hi, tol=1e-7):
    """All pairwise intersections of the 2m boundary lines that satisfy every constraint."""
    lines = [(N[i], b - t0[i]) for i in range(len(t0)) for b in (lo[i], hi[i])]
    pts = []
    for (a1, b1), (a2, b2) in itertools.combinations(lines, 2):
        A = np.array([a1, a2])
        if abs(np.linalg.det(A)) < 1e-12:
            continue
        lam = np.linalg.solve(A, [b1, b2])
        t = t0 + N @ lam
        if np.all(t >= lo - tol) and np.all(t <= hi + tol):
            pts.append(lam)
    uniq = []
    for p in pts:
        if all(np.linalg.norm(p - q) > 1e-6 for q in uniq):
            uniq.append(p)
    return np.array(uniq)


@pytest.mark.parametrize("robot_file", ROBOTS)
@pytest.mark.parametrize("near_limit", [False, True])
def test_polygon_vertices_brute_force_and_lp(robot_file, near_limit):
    model = load_robot(CONFIG / robot_file)
    ns = NullSpace(model.n_cables)
    rng = np.random.default_rng(11)
    for W, w, lo, hi in cases(model, 12, seed=1 + near_limit, near_limit=near_limit):
        assert ns.update(W, w)
        poly = feasible_polygon(ns.N, ns.t0, lo, hi)
        assert poly, "feasible by construction"
        V = np.array(poly)
        B = brute_force_vertices(ns.N, ns.t0, lo, hi)
        # every brute-force vertex is one of ours and vice versa (up to near-duplicates)
        for b in B:
            assert np.min(np.linalg.norm(V - b, axis=1)) < 1e-5
        for v in V:
            assert np.min(np.linalg.norm(B - v, axis=1)) < 1e-5
        # support function in random directions of tension space equals the LP optimum
        for _ in range(3):
            c = rng.normal(size=model.n_cables)
            res = lp_feasible(W, w, lo, hi, c=c)
            assert res.status == 0
            ours = min(c @ (ns.t0 + ns.N @ v) for v in V)
            assert ours == pytest.approx(res.fun, abs=1e-6 * max(1.0, abs(res.fun)))


@pytest.mark.parametrize("robot_file", ROBOTS)
def test_infeasibility_verdicts_agree_with_lp(robot_file):
    model = load_robot(CONFIG / robot_file)
    ns = NullSpace(model.n_cables)
    seen = {True: 0, False: 0}
    for W, w, lo, hi in cases(model, 30, seed=5, infeasible=True):
        ns.update(W, w)
        ours = bool(feasible_polygon(ns.N, ns.t0, lo, hi, eps=0.0))
        lp = lp_feasible(W, w, lo, hi).status == 0
        assert ours == lp
        seen[lp] += 1
    assert seen[False] > 0  # the generator does produce infeasible wrenches


def test_least_violating_matches_lp_minimax(rowc):
    ns = NullSpace(8)
    n = 0
    for W, w, lo, hi in cases(rowc, 30, seed=9, infeasible=True):
        ns.update(W, w)
        if feasible_polygon(ns.N, ns.t0, lo, hi):
            continue
        lam, s = least_violating(ns.N, ns.t0, lo, hi)
        t = ns.t0 + ns.N @ lam
        assert np.max(np.maximum(lo - t, t - hi)) == pytest.approx(s, abs=1e-9)
        # LP: min s  s.t.  W t = w,  lo − s <= t <= hi + s
        m = 8
        c = np.zeros(m + 1)
        c[-1] = 1.0
        A_ub = np.vstack(
            [np.hstack([-np.eye(m), -np.ones((m, 1))]), np.hstack([np.eye(m), -np.ones((m, 1))])]
        )
        b_ub = np.concatenate([-lo, hi])
        res = linprog(
            c,
            A_ub=A_ub,
            b_ub=b_ub,
            A_eq=np.hstack([W, np.zeros((6, 1))]),
            b_eq=w,
            bounds=[(None, None)] * (m + 1),
            method="highs",
        )
        assert s == pytest.approx(res.fun, abs=1e-6)
        n += 1
    assert n > 3


@pytest.mark.parametrize("robot_file", ROBOTS)
def test_barycenter_independent_of_null_space_basis(robot_file):
    """The area centroid is affine-equivariant: any basis and particular solution give the same
    tensions (checked with a random non-orthonormal basis and a shifted t0)."""
    model = load_robot(CONFIG / robot_file)
    ns = NullSpace(model.n_cables)
    rng = np.random.default_rng(3)
    for W, w, lo, hi in cases(model, 10, seed=2):
        ns.update(W, w)
        _, (x, y) = area_centroid(feasible_polygon(ns.N, ns.t0, lo, hi))
        t_ref = ns.t0 + ns.N @ [x, y]
        T = rng.normal(size=(2, 2)) + 2 * np.eye(2)
        N2 = ns.N @ T
        t0b = ns.t0 + ns.N @ rng.normal(scale=50.0, size=2)
        poly2 = feasible_polygon(N2, t0b, lo, hi)
        _, (x2, y2) = area_centroid(poly2)
        np.testing.assert_allclose(t0b + N2 @ [x2, y2], t_ref, atol=1e-6)


def quadprog_min_norm_t_space(W, w, lo, hi):
    """min ½‖t‖² s.t. W t = w, lo <= t <= hi — directly in tension space."""
    m = W.shape[1]
    C = np.hstack([W.T, np.eye(m), -np.eye(m)])
    b = np.concatenate([w, lo, -hi])
    return quadprog.solve_qp(np.eye(m), np.zeros(m), C, b, meq=6)[0]


@pytest.mark.parametrize("robot_file", ROBOTS)
@pytest.mark.parametrize("method", [TDAMethod.MIN_2NORM, TDAMethod.QP])
def test_bounded_min_2norm_equals_quadprog(robot_file, method):
    model = load_robot(CONFIG / robot_file)
    td = TensionDistributor(model, TDAOptions(method=method))
    for W, w, lo, hi in cases(model, 15, seed=4, near_limit=True):
        out = td.solve(W, w)
        assert out.status == TDAStatus.OK
        ref = quadprog_min_norm_t_space(W, w, lo, hi)
        np.testing.assert_allclose(out.tensions, ref, atol=1e-6 * max(1.0, hi.max()))
        assert out.residual <= 1e-9


@pytest.mark.parametrize("robot_file", ROBOTS)
def test_min_1norm_equals_linprog(robot_file):
    model = load_robot(CONFIG / robot_file)
    td = TensionDistributor(model, TDAOptions(method=TDAMethod.MIN_1NORM))
    for W, w, lo, hi in cases(model, 10, seed=6):
        out = td.solve(W, w)
        res = lp_feasible(W, w, lo, hi, c=np.ones(model.n_cables))
        assert out.tensions.sum() == pytest.approx(res.fun, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("robot_file", ROBOTS)
@pytest.mark.parametrize("method", list(TDAMethod))
def test_every_method_keeps_equilibrium_and_limits(robot_file, method):
    model = load_robot(CONFIG / robot_file)
    td = TensionDistributor(model, TDAOptions(method=method))
    d = KinematicsData(model)
    rng = np.random.default_rng(12)
    for p, R in random_poses(model, 8, rng, tilt=0.1):
        inverse_kinematics(model, d, p, R)
        w = d.W @ rng.uniform(model.tension_min, model.tension_max)
        k = model.cable_stiffness(d.length)
        out = td.solve(d.W, w, k=k, kin=d)
        assert out.residual <= 1e-9, (method, out.status)
        if out.status == TDAStatus.OK:
            assert np.all(out.tensions >= model.tension_min)
            assert np.all(out.tensions <= model.tension_max)
        else:  # only the baselines may leave the limits
            assert method in (TDAMethod.PINV, TDAMethod.CLOSED_FORM)


def test_general_redundancy_qp_and_energy_on_seven_and_nine_cables(seed000, caroca):
    """r = 1 (the Sensors robot without its first cable) and r = 3 (CAROCA with a cable
    doubled): QP equals quadprog in tension space and the energy minimum equals a direct
    weighted QP (min Σ t²/2k)."""
    checked = 0
    for base, cables in (
        (seed000, seed000.cables[1:]),
        (caroca, caroca.cables + caroca.cables[:1]),
    ):
        cables = tuple(dataclasses.replace(c, name=str(i + 1)) for i, c in enumerate(cables))
        model = dataclasses.replace(base, cables=cables)
        d = KinematicsData(model)
        inverse_kinematics(model, d, model.home.position, model.home.rotation)
        w = -model.gravity_wrench(model.home.rotation)
        lo, hi = model.tension_min, model.tension_max
        if lp_feasible(d.W, w, lo, hi).status != 0:
            continue
        out = TensionDistributor(model, TDAOptions(method=TDAMethod.QP)).solve(d.W, w)
        assert out.status == TDAStatus.OK
        np.testing.assert_allclose(
            out.tensions, quadprog_min_norm_t_space(d.W, w, lo, hi), atol=1e-5
        )
        k = model.cable_stiffness(d.length)
        out = TensionDistributor(model, TDAOptions(method=TDAMethod.ENERGY)).solve(d.W, w, k=k)
        m = model.n_cables
        C = np.hstack([d.W.T, np.eye(m), -np.eye(m)])
        ref = quadprog.solve_qp(
            np.diag(1.0 / k), np.zeros(m), C, np.concatenate([w, lo, -hi]), meq=6
        )[0]
        np.testing.assert_allclose(out.tensions, ref, atol=1e-4)
        checked += 1
    assert checked == 2


@pytest.fixture(scope="module")
def caroca():
    return load_robot(CONFIG / "caroca.toml")


# -- continuity, rate limit, failure ------------------------------------------------------


def _sweep(model, n=400):
    """A smooth straight motion across the workspace, gravity only."""
    d = KinematicsData(model)
    ws = model.workspace
    a = ws.position_min + 0.1 * (ws.position_max - ws.position_min)
    b = ws.position_max - 0.1 * (ws.position_max - ws.position_min)
    for s in np.linspace(0.0, 1.0, n):
        p = a + (b - a) * (3 * s**2 - 2 * s**3)
        inverse_kinematics(model, d, p, model.home.rotation)
        yield d, -model.gravity_wrench(model.home.rotation)


def test_barycenter_is_continuous_and_vertex_average_is_not(rowc):
    td = TensionDistributor(rowc, TDAOptions(method=TDAMethod.BARYCENTER))
    bary_jump = avg_jump = 0.0
    prev_b = prev_a = None
    changes = 0
    prev_nv = None
    for d, w in _sweep(rowc):
        out = td.solve(d.W, w)
        assert out.status == TDAStatus.OK
        t_b = out.tensions.copy()
        V = np.array(out.polygon)
        t_a = td.ns.t0 + td.ns.N @ V.mean(axis=0)  # the naive "vertex average"
        if prev_b is not None:
            bary_jump = max(bary_jump, np.abs(t_b - prev_b).max())
            avg_jump = max(avg_jump, np.abs(t_a - prev_a).max())
        if prev_nv is not None and len(V) != prev_nv:
            changes += 1
        prev_b, prev_a, prev_nv = t_b, t_a, len(V)
    assert changes > 0  # vertices appear and disappear along the way
    assert bary_jump < 1.0  # N per 5 mm step
    assert avg_jump > 5 * bary_jump


def test_tension_rate_limit(rowc):
    rate, period = 200.0, 0.002  # N/s, s: at most 0.4 N per cycle
    td = TensionDistributor(
        rowc, TDAOptions(method=TDAMethod.SOTDA, nu=1.0, max_tension_rate=rate, period=period)
    )
    prev = None
    limited = 0
    for d, w in _sweep(rowc, n=300):
        k = rowc.cable_stiffness(d.length)
        out = td.solve(d.W, w, k=k, kin=d, t_prev=prev)
        assert out.status == TDAStatus.OK and out.residual < 1e-9
        if prev is not None and not out.message:
            assert np.abs(out.tensions - prev).max() <= rate * period + 1e-6
        limited += out.rate_limited
        prev = out.tensions.copy()
    assert limited > 0


def test_infeasible_wrench_status_and_least_violating(rowc):
    td = TensionDistributor(rowc, TDAOptions(method=TDAMethod.BARYCENTER))
    d = KinematicsData(rowc)
    inverse_kinematics(rowc, d, rowc.home.position, rowc.home.rotation)
    w = -(rowc.gravity_wrench(np.eye(3)) + np.array([0, 2000.0, 0, 0, 0, 0]))
    out = td.solve(d.W, w)
    assert out.status == TDAStatus.INFEASIBLE
    assert out.max_violation > 0
    assert out.residual < 1e-9  # equilibrium kept, bounds violated by the least amount
    assert np.all(np.isfinite(out.tensions))


@pytest.mark.parametrize("method", list(TDAMethod))
def test_never_raises_never_nan_never_ok_out_of_limits(rowc, method):
    td = TensionDistributor(rowc, TDAOptions(method=method))
    rng = np.random.default_rng(99)
    d = KinematicsData(rowc)
    inverse_kinematics(rowc, d, rowc.home.position, rowc.home.rotation)
    k = rowc.cable_stiffness(d.length)
    bad_inputs = [
        (np.full((6, 8), np.nan), np.zeros(6)),
        (np.zeros((6, 8)), np.ones(6)),
        (d.W, np.full(6, np.inf)),
        (d.W, np.array([np.nan, 0, 0, 0, 0, 0])),
        (d.W[:, [0] * 8], np.ones(6)),  # rank 1
        (d.W, np.array([0, 0, 1e9, 0, 0, 0])),
    ]
    for _ in range(30):
        bad_inputs.append((d.W + rng.normal(scale=0.3, size=(6, 8)), rng.normal(scale=300, size=6)))
    for W, w in bad_inputs:
        out = td.solve(W, w, k=k, kin=d, t_prev=np.full(8, 50.0))
        assert np.all(np.isfinite(out.tensions))
        if out.status == TDAStatus.OK:
            assert np.all(out.tensions >= rowc.tension_min)
            assert np.all(out.tensions <= rowc.tension_max)
            assert out.residual < 1e-6


@pytest.mark.parametrize("method", list(TDAMethod))
def test_an_unusable_solve_gives_the_last_tensions_within_the_limits(rowc, method):
    """A wrench no solve can use (NaN): the last tensions, clipped to [t_min, t_max] — last
    tensions from beyond the limits (the limits lowered since) come back within them."""
    td = TensionDistributor(rowc, TDAOptions(method=method))
    d = KinematicsData(rowc)
    inverse_kinematics(rowc, d, rowc.home.position, rowc.home.rotation)
    k = rowc.cable_stiffness(d.length)
    prev = np.r_[1.5 * rowc.tension_max[:4], 0.5 * rowc.tension_min[4:]]  # N
    out = td.solve(d.W, np.full(6, np.nan), k=k, kin=d, t_prev=prev)
    assert out.status in (TDAStatus.DEGENERATE, TDAStatus.INTERNAL_ERROR)
    expected = np.r_[rowc.tension_max[:4], rowc.tension_min[4:]]
    np.testing.assert_array_equal(out.tensions, expected)


def test_options_validated_outside_the_loop(seed000):
    from cdprctl.tda import ImposedQuantity, Imposition

    with pytest.raises(ValueError, match=r"nu = 1.5 must be in \[0, 1\]"):
        TensionDistributor(seed000, TDAOptions(method=TDAMethod.SOTDA, nu=1.5))
    with pytest.raises(ValueError, match="at most r = 2"):
        TensionDistributor(
            seed000,
            TDAOptions(
                method=TDAMethod.ENERGY,
                impositions=tuple(Imposition(i, ImposedQuantity.ENERGY, 10.0) for i in range(3)),
            ),
        )
    with pytest.raises(ValueError, match="tension = 900 N is outside"):
        TensionDistributor(
            seed000,
            TDAOptions(
                method=TDAMethod.ENERGY,
                impositions=(Imposition(0, ImposedQuantity.TENSION, 900.0),),
            ),
        )
    assert math.isfinite(TDAOptions().nu)


def test_energy_two_impositions_fast_path_equals_the_general_one(seed000):
    """r = 2 with two impositions: the 2×2 solve against the general QR + minimum-energy path
    (`cdprctl.tda.energy.impose`/`minimum_energy`) over random feasible targets."""
    import math

    from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
    from cdprctl.tda import ImposedQuantity, Imposition, TDAMethod, TDAOptions, TensionDistributor
    from cdprctl.tda.energy import impose, minimum_energy

    rng = np.random.default_rng(7)
    kin = KinematicsData(seed000)
    inverse_kinematics(seed000, kin, seed000.home.position, seed000.home.rotation)
    k = seed000.cable_stiffness(kin.length)
    w = -seed000.gravity_wrench(seed000.home.rotation)
    base = TensionDistributor(seed000, TDAOptions(method=TDAMethod.BARYCENTER)).solve(kin.W, w)
    checked = 0
    for _ in range(40):
        t1, t8 = base.tensions[0] + rng.uniform(-40, 40), base.tensions[7] + rng.uniform(-40, 40)
        imps = (
            Imposition(0, ImposedQuantity.TENSION, t1),
            Imposition(7, ImposedQuantity.TENSION, t8),
        )
        tda = TensionDistributor(seed000, TDAOptions(method=TDAMethod.ENERGY, impositions=imps))
        out = tda.solve(kin.W, w, k=k)
        ns = tda.ns
        free = impose(ns.N, ns.t0, [0, 7], [t1, t8])
        sol = minimum_energy(ns.N, ns.t0, k, seed000.tension_min, seed000.tension_max, free)
        if not sol.feasible:
            continue
        checked += 1
        assert out.ok
        np.testing.assert_allclose(out.tensions, ns.t0 + ns.N @ sol.lam, atol=1e-8)
        assert out.tensions[0] == pytest.approx(t1) and out.tensions[7] == pytest.approx(t8)
        assert math.isnan(out.energy_range[0, 0]) and math.isnan(out.energy_range[7, 1])
        np.testing.assert_allclose(out.energy_range[1], out.tensions[1] ** 2 / (2 * k[1]))
    assert checked > 20


def test_sotda_grid_candidates_match_a_numpy_meshgrid():
    """The compiled grid of the SOTDA's grid variant: numpy's meshgrid of two linspaces, the
    points left of every edge, then the vertices — point for point, on random polygons."""
    from cdprctl.tda.sotda import grid_candidates

    rng = np.random.default_rng(11)
    for _ in range(100):
        ang = np.sort(rng.uniform(0.0, 2.0 * np.pi, rng.integers(3, 9)))
        radius = rng.uniform(1.0, 50.0)
        P = np.stack([np.cos(ang), np.sin(ang)], axis=1) * radius + rng.normal(0.0, 100.0, 2)
        n = int(rng.integers(2, 80))
        gx, gy = np.meshgrid(
            np.linspace(P[:, 0].min(), P[:, 0].max(), n),
            np.linspace(P[:, 1].min(), P[:, 1].max(), n),
        )
        pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
        inside = np.ones(len(pts), dtype=bool)
        for (px, py), (qx, qy) in zip(P, np.roll(P, -1, axis=0), strict=True):
            ex, ey = qx - px, qy - py
            cross = ex * (pts[:, 1] - py) - ey * (pts[:, 0] - px)
            inside &= cross / max(abs(ex) + abs(ey), 1e-300) >= -1e-12
        np.testing.assert_array_equal(grid_candidates(P, n), np.concatenate([pts[inside], P]))
