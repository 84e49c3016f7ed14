"""The tension distribution in the loop (control/cycle/distribution.py): a switch of method swaps
distributors built at start-up (none is built in the cycle) and blends from the old one; every
blend holds the wrench inside the limits; the old one is dropped after BLEND_TIME."""

from __future__ import annotations

from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from conftest import FakeDrives

from cdprctl.control.cycle.controller import Controller
from cdprctl.control.cycle.distribution import Distribution
from cdprctl.robot_file import load_robot
from cdprctl.tda import ImposedQuantity, Imposition, TDAMethod, TDAOptions, TensionDistributor
from drivers.vocabulary import Lifecycle

ROOT = Path(__file__).resolve().parents[3]
ROWC = load_robot(ROOT / "config" / "rowc.toml")


@pytest.fixture()
def at_home():
    """A controller whose estimate is the home pose (θ = 0: the home lengths); rowc is in
    position mode, so its distribution works at the reference, the home pose too."""
    c = Controller(ROWC, FakeDrives(ROWC.n_cables, Lifecycle.INACTIVE))
    m = ROWC.n_cables
    c.estimator.update(0.0, np.zeros(m), ROWC.tension_min.copy())
    c.data.wrench[:] = c.pose.gravity_hold(c.at.rotation, c.data.ext_total)
    return c


def reference(options: TDAOptions, c: Controller) -> np.ndarray:
    """The tensions a fresh distributor gives at the loop's working pose (independent of the
    loop's distributors)."""
    e, dist = c.at, c.distribution
    out = TensionDistributor(ROWC, options).solve(
        e.kin.W, c.data.wrench, dist.t_min, dist.t_max, k=e.k, kin=e.kin
    )
    assert out.ok
    return out.tensions.copy()


def test_every_method_the_robot_can_use_is_built_at_start_up(at_home):
    dist = at_home.distribution
    assert set(dist.methods) == {
        m for m in TDAMethod if not TDAOptions(method=m).validate(ROWC)
    }  # r = 2: the polygon methods too
    assert TDAMethod.SOTDA in dist.methods and TDAMethod.QP in dist.methods


def test_switching_builds_nothing_and_blends(at_home):
    c = at_home
    d, dist, W = c.data, c.distribution, c.at.kin.W
    bary = TDAOptions(method=TDAMethod.BARYCENTER, period=ROWC.control.period)
    energy = TDAOptions(method=TDAMethod.ENERGY, period=ROWC.control.period)
    dist.switch(bary, 0.0, blend=False)
    t_old, t_new = reference(bary, c), reference(energy, c)
    assert np.abs(t_new - t_old).max() > 1.0  # the two methods differ here
    with mock.patch.object(TensionDistributor, "__init__", side_effect=AssertionError("built")):
        dist.switch(energy, 10.0, blend=True)
        for s in (0.0, 0.25, 0.5, 0.75, 0.999):
            d.time = 10.0 + s * Distribution.BLEND_TIME
            dist.distribute(c.at)
            expect = (1.0 - s) * t_old + s * t_new
            np.testing.assert_allclose(d.tensions, expect, atol=1e-6)
            np.testing.assert_allclose(W @ d.tensions, d.wrench, atol=1e-6)
            assert np.all(d.tensions >= dist.t_min - 1e-9)
            assert np.all(d.tensions <= dist.t_max + 1e-9)
        d.time = 10.0 + Distribution.BLEND_TIME
        dist.distribute(c.at)
        assert dist.old is None
        dist.impose((Imposition(7, ImposedQuantity.TENSION, 100.0),))
    assert dist.options.method is TDAMethod.ENERGY and d.tda_method == "energy"


def test_a_switch_while_blending_blends_from_the_current_one(at_home):
    c = at_home
    d, dist = c.data, c.distribution
    p = ROWC.control.period
    a, b, e = (
        TDAOptions(method=TDAMethod(x), period=p) for x in ("barycenter", "min-2-norm", "energy")
    )
    dist.switch(a, 0.0, blend=False)
    dist.switch(b, 1.0, blend=True)
    d.time = 1.5
    dist.switch(e, 1.5, blend=True)
    assert dist.old is not None and dist.old.options.method is TDAMethod.MIN_2NORM
    assert dist.current.options.method is TDAMethod.ENERGY
    assert dist.current is not dist.old
    d.time = 1.5
    dist.distribute(c.at)
    np.testing.assert_allclose(d.tensions, reference(b, c), atol=1e-6)


def test_the_stretch_distribution_switches_with_the_loops(at_home):
    c = at_home
    dist = c.distribution
    p = ROWC.control.period
    sotda = TDAOptions(method=TDAMethod.SOTDA, nu=0.9, period=p)
    dist.switch(sotda, 0.0, blend=False)
    assert dist.static.options == sotda and dist.static is not dist.current
    assert dist.stretch(c.data.wrench, c.at)
    np.testing.assert_allclose(c.data.stretch_tensions, reference(sotda, c), atol=1e-6)


def feasible_lp(W: np.ndarray, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Independent check (scipy's HiGHS): some t in [lo, hi] with W t = w."""
    from scipy.optimize import linprog

    res = linprog(np.zeros(W.shape[1]), A_eq=W, b_eq=w, bounds=list(zip(lo, hi, strict=True)))
    return bool(res.status == 0)


@pytest.mark.parametrize("push", [[0.0, 600.0, 0.0], [900.0, 0.0, 0.0], [0.0, 0.0, 2000.0]])
def test_an_infeasible_wrench_is_saturated_not_dropped(at_home, push):
    """The PID asks for more than the cables can give: its feedback part is scaled to the
    largest fraction that stays feasible (scipy's LP agrees at s, and disagrees 1e-3 beyond),
    the feed-forward kept whole, the tensions inside their limits."""
    c = at_home
    d, dist, W = c.data, c.distribution, c.at.kin.W
    ff = c.pose.gravity_hold(c.at.rotation, c.data.ext_total)
    fb = np.array([*push, 0.0, 0.0, 0.0])
    assert not feasible_lp(W, ff + fb, dist.t_min, dist.t_max)
    d.wrench[:] = ff + fb
    d.feedback_wrench[:] = fb
    d.tensions[:] = d.hold_tensions[:] = dist.t_min
    out = dist.distribute(c.at)
    s = d.saturation
    assert out.ok and 0.0 < s < 1.0 and dist.bad_cycles == 0
    np.testing.assert_allclose(d.wrench, ff + s * fb, atol=1e-9)
    np.testing.assert_allclose(W @ d.tensions, ff + s * fb, atol=1e-6)
    assert np.all(d.tensions >= dist.t_min - 1e-9) and np.all(d.tensions <= dist.t_max + 1e-9)
    assert feasible_lp(W, ff + s * fb, dist.t_min - 1e-6, dist.t_max + 1e-6)
    assert not feasible_lp(W, ff + (s + 1e-3) * fb, dist.t_min, dist.t_max)


def test_an_infeasible_feed_forward_holds_the_last_tensions(at_home):
    c = at_home
    d, dist = c.data, c.distribution
    d.hold_tensions[:] = np.linspace(20.0, 30.0, ROWC.n_cables)
    d.wrench[:] = [0.0, 0.0, 1e5, 0.0, 0.0, 0.0]  # 100 kN up: no tensions hold that
    d.feedback_wrench[:] = 0.0
    out = dist.distribute(c.at)
    assert not out.ok and d.saturation == 1.0 and dist.bad_cycles == 1
    np.testing.assert_allclose(d.tensions, d.hold_tensions)
