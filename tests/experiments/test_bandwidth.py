"""The closed loop's bandwidth per axis on rowc (issue goal: ≥ 1.5 Hz in every axis), lock-step:
the reference moved by a 1 mm (1 mrad) sinusoid, the simulated platform's pose fitted
(``cdprctl/experiments/bandwidth.py``; the table at more frequencies: ``tools/bandwidth_table.py``,
docs/control.md)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from cdprctl.experiments.bandwidth import AXES, Response, _fit, bandwidth, response


def test_the_fit_recovers_a_known_sinusoid():
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 2.0, 501)
    w = 2.0 * math.pi * 1.5
    y = 0.7 * np.sin(w * t - 0.3) + 0.2 + 1e-4 * rng.standard_normal(t.size)
    z = _fit(t, y, w)
    assert abs(z) == pytest.approx(0.7, abs=1e-3)
    assert np.angle(z) == pytest.approx(-0.3, abs=1e-3)


def test_bandwidth_interpolates_where_the_gain_falls():
    rs = [Response(0, f, g, 0.0, "enabled") for f, g in ((1.0, 1.0), (2.0, 0.9), (4.0, 0.5))]
    f = bandwidth(rs)
    assert 2.0 < f < 4.0
    assert bandwidth(rs[:2]) == math.inf
    assert math.isnan(bandwidth([Response(0, 1.0, 0.5, 0.0, "enabled")]))
    assert bandwidth([*rs[:2], Response(0, 3.0, math.nan, 0.0, "fault")]) == 2.0


def test_every_axis_follows_1_5_hz(rowc):
    """Position mode: the drives' loops (50 Hz) hold the lengths the reference asks for, so
    every axis — y too, which rowc's cables hold only through their elasticity — follows a
    1.5 Hz reference within ±3 dB (measured 1.00-1.01, lag under 6°; the first axis to fall
    below −3 dB does so at 11.5 Hz). With the drives' loops at 1 Hz none does: the bandwidth
    is theirs (the translations fall to 0.04-0.33, the rotations, held by little more than
    the feed-forward tensions, ring at 1.56-1.70)."""
    for axis in range(6):
        r = response(rowc, axis, 1.5)
        assert r.state == "enabled", AXES[axis]
        assert 1.0 / math.sqrt(2.0) < r.gain < math.sqrt(2.0), (AXES[axis], r)
        assert abs(r.phase) < math.radians(20.0), (AXES[axis], r)
    slow = dataclasses.replace(rowc.drives, position_loop_bandwidth=1.0)
    slow_rowc = dataclasses.replace(rowc, drives=slow)
    for axis in range(6):
        gain = response(slow_rowc, axis, 1.5).gain
        assert not 1.0 / math.sqrt(2.0) < gain < math.sqrt(2.0), (AXES[axis], gain)
