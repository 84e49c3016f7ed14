"""The scalar rules of ``cdprctl/core/numerics.py`` at the unit level, compiled and plain, against
numbers worked by hand and numpy: a motor step's plausibility at its bound, each term of the
cable law, a cable's terms from its file's fields, the unstretched length the law inverts, the
stiffness per cable, the worst element against its limit, the sum and the largest (mutation
testing found these held only through the closed loops, or not at all:
tools/mutation_results.json)."""

from __future__ import annotations

import dataclasses
import functools
import math
import operator
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.core.numerics import (
    Compliance,
    cable_compliance,
    cable_compliance_py,
    compliance_of,
    compliance_terms,
    forward_substitution,
    kernel_args,
    largest,
    plausible_step,
    plausible_step_py,
    stiffness_kernel,
    total,
    unstretched_lengths,
    worst_ratio,
)
from cdprctl.robot_file import load_robot

CABLE = load_robot(CONFIG / "rowc.toml").cables[0]


@pytest.mark.parametrize("rule", [plausible_step, plausible_step_py], ids=["njit", "python"])
def test_a_step_is_plausible_up_to_the_speed_times_the_time_and_slack(rule):
    """The bound itself is plausible, beyond it not; an elapsed time that ran backwards counts
    as none (only the slack); a non-finite step never."""
    speed, elapsed, slack = 40.0, 0.004, 0.002  # rad/s, s, s
    bound = speed * (elapsed + slack)  # 0.24 rad
    assert rule(bound, speed, elapsed, slack) and rule(-bound, speed, elapsed, slack)
    assert not rule(bound * (1 + 1e-9), speed, elapsed, slack)
    assert rule(speed * slack, speed, -0.5, slack)  # the clock went back: the slack alone
    assert not rule(speed * slack * 1.01, speed, -0.5, slack)
    assert not rule(speed * slack * 1.01, speed, 0.0, slack)
    assert rule(0.5 * speed * slack, speed, 0.0, slack)
    assert not rule(math.nan, speed, elapsed, slack) and not rule(math.inf, speed, elapsed, slack)


@pytest.mark.parametrize("rule", [cable_compliance, cable_compliance_py], ids=["njit", "python"])
def test_the_cable_law_sums_a_fixed_compliance_the_elastic_length_and_the_spring(rule):
    """1/k = 1/k_fixed + (l + l_w)/(E S) + 1/k_s, each term apart and all together (m/N)."""
    assert rule(2e-5, 0.0, 0.0, 0.0, 7.0) == pytest.approx(2e-5, rel=1e-15)
    assert rule(0.0, 3e-7, 1.5, 0.0, 4.0) == pytest.approx(3e-7 * 5.5, rel=1e-15)
    assert rule(0.0, 0.0, 0.0, 4e-5, 4.0) == pytest.approx(4e-5, rel=1e-15)
    assert rule(2e-5, 3e-7, 1.5, 4e-5, 4.0) == pytest.approx(2e-5 + 3e-7 * 5.5 + 4e-5, rel=1e-15)


def test_a_cables_terms_from_its_fields():
    """``(1/k_fixed, 1/(E S), l_w, 1/k_s)``: a fixed stiffness, or the modulus and section (any
    positive product), a series spring, the length to the winch; E S needs both; an object
    without ``length_to_winch`` has none."""
    fixed = dataclasses.replace(CABLE, stiffness=5e4, youngs_modulus=None, cross_section=None,
                                spring_stiffness=2e3, length_to_winch=1.25)  # fmt: skip
    assert compliance_terms(fixed) == pytest.approx((2e-5, 0.0, 1.25, 5e-4), rel=1e-15)
    elastic = dataclasses.replace(CABLE, stiffness=None, youngs_modulus=1e11, cross_section=2e-6,
                                  spring_stiffness=None, length_to_winch=0.0)  # fmt: skip
    assert compliance_terms(elastic) == pytest.approx((0.0, 5e-6, 0.0, 0.0), rel=1e-15)
    tiny = dataclasses.replace(elastic, youngs_modulus=2.0, cross_section=0.25)  # E S = 0.5 N
    assert compliance_terms(tiny)[1] == 2.0
    for e, s in ((None, 2e-6), (1e11, None), (None, None)):
        half = dataclasses.replace(elastic, youngs_modulus=e, cross_section=s)
        assert compliance_terms(half) == (0.0, 0.0, 0.0, 0.0), (e, s)
    bare = SimpleNamespace(stiffness=5e4, spring_stiffness=None)
    assert compliance_terms(bare) == (2e-5, 0.0, 0.0, 0.0)


def test_the_unstretched_length_carries_its_tension_to_the_geometric_length():
    """l0 such that l0 + t·c(l0) = l, c the cable law at the unstretched length, for each kind
    of cable (three cables, three tensions)."""
    law = Compliance(
        inv_k_fixed=np.array([2e-5, 0.0, 1e-5]),
        inv_es=np.array([0.0, 4e-6, 2e-6]),
        l_winch=np.array([0.0, 1.5, 0.75]),
        inv_spring=np.array([0.0, 0.0, 3e-4]),
    )
    lengths, tensions = np.array([3.0, 4.0, 5.0]), np.array([100.0, 250.0, 40.0])
    l0 = unstretched_lengths(law, lengths, tensions)
    for i in range(3):
        c = cable_compliance_py(law.inv_k_fixed[i], law.inv_es[i], law.l_winch[i],
                                law.inv_spring[i], l0[i])  # fmt: skip
        assert l0[i] + tensions[i] * c == pytest.approx(lengths[i], rel=0, abs=1e-13)
    # worked by hand for the second: l0 (1 + 250·4e-6) = 4 − 250·4e-6·1.5
    assert l0[1] == pytest.approx((4.0 - 250 * 4e-6 * 1.5) / (1.0 + 250 * 4e-6), rel=1e-15)
    assert np.all(l0 < lengths)


def test_the_stiffness_of_each_cable_is_one_over_its_compliance_at_its_length():
    fixed = dataclasses.replace(CABLE, stiffness=5e4, spring_stiffness=None, length_to_winch=0.0)
    elastic = dataclasses.replace(CABLE, stiffness=None, youngs_modulus=1e11, cross_section=2e-6,
                                  spring_stiffness=2e3, length_to_winch=1.0)  # fmt: skip
    cables = [fixed, elastic]
    law = compliance_of(cables)
    lengths, out = np.array([3.0, 4.0]), np.full(2, np.nan)
    stiffness_kernel(lengths, kernel_args(law), out)
    assert out == pytest.approx([5e4, 1.0 / (5e-6 * 5.0 + 5e-4)], rel=1e-14)


def test_the_lower_triangular_solve_against_numpy():
    rng = np.random.default_rng(3)
    L = np.tril(rng.normal(size=(6, 6))) + 4.0 * np.eye(6)
    b, y = rng.normal(size=6), np.full(6, np.nan)
    forward_substitution(L, b, y)
    np.testing.assert_allclose(y, np.linalg.solve(L, b), rtol=1e-13, atol=1e-14)


def test_the_worst_element_against_its_limit_is_numpys_first_argmax():
    """Signed values, limits per element, all below their limits (the common case) or one
    beyond, ties (the first wins, as numpy's argmax), the worst anywhere but first."""
    rng = np.random.default_rng(11)
    for _ in range(200):
        n = int(rng.integers(1, 10))
        limits = rng.uniform(0.5, 3.0, n)
        values = rng.uniform(-1.0, 1.0, n) * limits * rng.choice([0.3, 1.5])
        assert worst_ratio(values, limits) == int(np.argmax(np.abs(values) / limits))
    limits = np.array([2.0, 1.0, 4.0, 1.0])
    assert worst_ratio(np.array([0.2, -0.5, 1.0, 0.1]), limits) == 1  # all < 1 of their limit
    assert worst_ratio(np.array([1.0, -0.5, 2.0, 0.5]), limits) == 0  # tied at 0.5: the first
    assert worst_ratio(np.array([0.0, 0.0, 0.0, -0.3]), limits) == 3


def test_the_sum_and_the_largest_are_pythons_of_the_list():
    """``total`` and ``largest`` replace ``sum`` and ``max`` of ``tolist()`` in the cycle:
    the same floats, bit for bit (left to right from 0, as ``sum`` up to Python 3.11), the
    first greatest, a NaN passed over unless first, and inf or NaN surviving the sum."""
    rng = np.random.default_rng(3)
    for _ in range(200):
        v = rng.normal(size=int(rng.integers(1, 12))) * 10.0 ** rng.integers(-3, 4)
        assert total(v) == functools.reduce(operator.add, v.tolist(), 0.0)
        assert largest(v) == max(v.tolist())
    assert total(np.array([1e16, 1.0, -1e16])) == 0.0  # not compensated: as 3.11's sum
    assert largest(np.array([1.0, 3.0, 2.0])) == 3.0
    assert largest(np.array([1.0, math.nan, 0.5])) == 1.0
    assert math.isnan(largest(np.array([math.nan, 2.0])))
    assert math.isinf(total(np.array([1.0, math.inf]))) and math.isnan(total(np.array([math.nan])))
