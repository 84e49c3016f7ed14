"""Each winch's friction (docs/friction.md): the fit against synthetic torques written out here
(statics, internal tensions, the law in numpy), its residual check on a friction the law does
not explain, ``--plant-errors``' draws, the record, the terms reaching the torque law and the
observer, and the whole procedure in lock-step on rowc with each winch 30-50 % off the file."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.calibration.calibration_record import CalibrationError
from cdprctl.calibration.friction import fit_measured, fit_winches, null_projectors, refusal
from cdprctl.control.cycle.torques import WinchTorques
from cdprctl.robot_file import load_robot
from sim_backend.plant_errors import PlantErrors

SMOOTHING, STRIBECK = 0.05, 2.0  # rad/s, the law's constants as numerics.py documents them


def law(w, b, tc, ts):
    """N·m: ``b w + (τ_c + τ_s exp(−(w/ω_s)²)) tanh(w/ω_ε)``, written out."""
    return b * w + (tc + ts * np.exp(-((w / STRIBECK) ** 2))) * np.tanh(w / SMOOTHING)


def synthetic(seed: int, bump: int | None = None):
    """Samples of an 8-cable robot out and back along three lines at three speeds (cosine
    time laws): per winch a statics function of the line's fraction, internal tensions of
    ±300 N in a random null space that follow the motion's sign (the drives' lags), the
    friction law, J θ̈ and 1 mN·m of noise. ``bump``: that winch's friction also binds
    over a fifth of each line (a bearing), 0.03 N·m."""
    rng = np.random.default_rng(seed)
    m, period = 8, 0.004
    r = np.full(m, 0.009)
    truth = {"b": rng.uniform(2e-4, 8e-4, m), "tc": rng.uniform(0.015, 0.045, m),
             "ts": rng.uniform(0.005, 0.02, m), "J": np.full(m, 1.5e-4)}  # fmt: skip
    Ws = [rng.normal(size=(6, m)) for _ in range(3)]  # each line's wrench matrix, constant
    rows = {k: [] for k in ("s", "line", "W", "w", "a", "tau", "t")}
    for j in range(3):
        rate = rng.uniform(-60.0, 60.0, m)  # rad of motor per unit of the line's fraction
        static = rng.uniform(0.2, 1.5, (m, 4))  # N·m: a cubic in s per winch
        _, _, vt = np.linalg.svd(Ws[j])
        N = vt[6:].T
        for v in (0.1, 0.3, 0.6):  # the line's fraction per second, mean
            T = 1.0 / v
            f = np.arange(0.0, T, period) / T
            for way in (1.0, -1.0):
                s = 0.5 - 0.5 * np.cos(np.pi * f) if way > 0 else 0.5 + 0.5 * np.cos(np.pi * f)
                sd = way * 0.5 * np.pi / T * np.sin(np.pi * f)
                sdd = way * 0.5 * (np.pi / T) ** 2 * np.cos(np.pi * f) * way
                w, a = np.outer(sd, rate), np.outer(sdd, rate)
                lam = 300.0 * np.outer(np.tanh(sd / 0.01), rng.uniform(-1, 1, m - 6))
                tau = static[:, 0] + np.outer(s, static[:, 1]) + np.outer(s**2, static[:, 2])
                tau += np.outer(s**3, static[:, 3])
                tau += (lam @ N.T) * r
                tau += law(w, truth["b"], truth["tc"], truth["ts"]) + truth["J"] * a
                if bump is not None:
                    near = (np.abs(s - 0.5) < 0.1).astype(float)
                    tau[:, bump] += 0.03 * near * np.tanh(w[:, bump] / SMOOTHING)
                tau += rng.normal(scale=1e-3, size=tau.shape)
                t = len(rows["t"]) * 100.0 + np.arange(len(s)) * period  # s: a gap between
                for k, x in (("s", s), ("line", np.full(len(s), j)), ("w", w), ("a", a),
                             ("tau", tau), ("t", t)):  # fmt: skip
                    rows[k].append(x)
                rows["W"].append(np.broadcast_to(Ws[j], (len(s), 6, m)))
    data = {k: np.concatenate(x) for k, x in rows.items()}
    data["Q"] = null_projectors(data["W"], r)
    return data, truth


def test_the_fit_finds_the_law_through_the_statics_and_the_internal_tensions():
    data, truth = synthetic(3)
    m = data["w"].shape[1]
    fits = fit_winches(data["s"], data["line"].astype(int), data["Q"], data["w"], data["a"],
                       data["tau"], np.full(m, 1e-3), np.zeros_like(data["w"]))  # fmt: skip
    for i, f in enumerate(fits):
        assert f.viscous == pytest.approx(truth["b"][i], rel=0.02)
        assert f.coulomb == pytest.approx(truth["tc"][i], rel=0.02)
        assert f.stribeck == pytest.approx(truth["ts"][i], rel=0.05, abs=1e-3)
        assert f.inertia == pytest.approx(truth["J"][i], rel=0.2)  # a small signal
        # the σ a fit claims is of the error it makes (within 5 σ, with a floor)
        assert abs(f.viscous - truth["b"][i]) < 5 * f.std[0] + 1e-6
        assert f.explained and f.pulley is None and f.pulley_note == "no pulley"
    assert refusal([str(i) for i in range(m)], fits) == ""


def test_a_winch_with_a_load_cell_is_fitted_on_its_tension_alone():
    """The torques of ``synthetic`` with each cable's tension known (a cell of 0.1 N noise and
    a 2 N offset, r × it taken off): every winch's law without the projection, to 2 %."""
    from cdprctl.calibration.friction_procedure import motion_of

    data, truth = synthetic(5)
    r, rng, period = 0.009, np.random.default_rng(6), 0.004
    # the tension each torque carries: what ``synthetic`` put in besides the law and J θ̈
    law_part = law(data["w"], truth["b"], truth["tc"], truth["ts"]) + truth["J"] * data["a"]
    tension = (data["tau"] - law_part) / r
    load = r * (tension + 2.0 + rng.normal(scale=0.1, size=tension.shape))
    rate = motion_of(load, data["t"], period)[0]
    line = data["line"].astype(int)
    for i in range(tension.shape[1]):
        f = fit_measured(data["s"], line, data["w"][:, i], data["a"][:, i], data["tau"][:, i],
                         load[:, i], rate[:, i], 1e-3, np.zeros(len(load)))  # fmt: skip
        assert f.source == "load cell" and f.explained
        assert f.viscous == pytest.approx(truth["b"][i], rel=0.02)
        assert f.coulomb == pytest.approx(truth["tc"][i], rel=0.02)
        assert f.stribeck == pytest.approx(truth["ts"][i], rel=0.05, abs=1e-3)
        assert f.inertia == pytest.approx(truth["J"][i], rel=0.2)


def test_a_binding_bearing_is_refused_by_name():
    data, _ = synthetic(4, bump=5)
    m = data["w"].shape[1]
    fits = fit_winches(data["s"], data["line"].astype(int), data["Q"], data["w"], data["a"],
                       data["tau"], np.full(m, 1e-3), np.zeros_like(data["w"]))  # fmt: skip
    why = refusal([f"c{i}" for i in range(m)], fits)
    assert why.startswith("winch c5: the residual RMS") and "exceeds its limit" in why
    assert max(fits, key=lambda f: f.residual_rms).residual_rms == fits[5].residual_rms


def test_plant_errors_draw_each_winchs_friction_and_keep_the_geometry():
    model = load_robot(CONFIG / "rowc.toml")
    plain, e0 = PlantErrors(7).apply(model)
    off, e1 = PlantErrors(7, friction=(0.3, 0.5), stribeck=0.5, pulley=0.04).apply(model)
    assert e0["anchor_offsets"] == e1["anchor_offsets"] and e0["drum_scales"] == e1["drum_scales"]
    for c, p in zip(model.cables, off.cables, strict=True):
        for key in ("viscous_friction", "coulomb_friction"):
            ratio = getattr(p.winch, key) / getattr(c.winch, key)
            assert 0.3 - 1e-12 <= abs(ratio - 1.0) <= 0.5 + 1e-12
        assert p.winch.stribeck_friction == pytest.approx(0.5 * p.winch.coulomb_friction)
        assert p.winch.pulley_friction == 0.04
    for c, p in zip(model.cables, plain.cables, strict=True):  # without: the file's friction
        assert (p.winch.viscous_friction, p.winch.coulomb_friction) == (
            c.winch.viscous_friction, c.winch.coulomb_friction)
    scales = np.array(e1["friction_scales"])
    assert np.any(scales > 1.0) and np.any(scales < 1.0)  # both ways


def test_the_record_checks_its_friction(tmp_path):
    from cdprctl.calibration.calibration_record import load, save, stamped

    model = load_robot(CONFIG / "rowc.toml")
    m = model.n_cables
    rec = stamped(model, "known-pose", theta_zero=[0.0] * m, drum_scale=[1.0] * m,
                  pose=[0.0] * 6, identities=[None] * m)  # fmt: skip
    rec.friction = {"time": "t", "viscous": [1e-4] * m, "coulomb": [0.02] * m,
                    "stribeck": [0.0] * m, "pulley": [0.0] * m}  # fmt: skip
    save(rec, tmp_path)
    back = load(tmp_path)
    back.check(model)
    assert back.friction == rec.friction
    back.friction["coulomb"][2] = math.nan
    with pytest.raises(CalibrationError, match=r"friction.coulomb: .* is not 8 finite"):
        back.check(model)


def test_applied_friction_reaches_the_torques_and_the_observer():
    from cdprctl.control.cycle.observer import WrenchObserver
    from cdprctl.control.data import ControlData

    model = load_robot(CONFIG / "rowc.toml")
    model = dataclasses.replace(
        model, control=dataclasses.replace(model.control, friction_compensation=True))
    wt = WinchTorques(model)
    obs = WrenchObserver(model, ControlData(model.n_cables, 0), wt)
    m = model.n_cables
    wt.apply_friction([1e-3] * m, [0.05] * m, [0.01] * m, [0.0] * m)
    out = np.empty(m)
    w = np.full(m, 10.0)
    wt.update(np.zeros(m), np.zeros((m, 6)), np.zeros(6), w, True, out)
    np.testing.assert_allclose(out, law(w, 1e-3, 0.05, 0.01), rtol=1e-12)
    # the observer takes the same arrays back out of the measured torques
    assert obs.winches.terms[2] is wt.coulomb and obs.winches.terms[3] is wt.stribeck


def test_the_robot_file_takes_each_winchs_stribeck_and_pulley_terms(tmp_path):
    from cdprctl.model.errors import ConfigError

    text = (CONFIG / "rowc.toml").read_text()
    f = tmp_path / "r.toml"
    f.write_text(text.replace("coulomb_friction = 0.03  # N·m at the motor (assumed)",
                              "coulomb_friction = 0.03\nstribeck_friction = 0.01\n"
                              "pulley_friction = 0.05"), encoding="utf-8")  # fmt: skip
    model = load_robot(f)
    assert {c.winch.stribeck_friction for c in model.cables} == {0.01}
    assert {c.winch.pulley_friction for c in model.cables} == {0.05}
    assert load_robot(CONFIG / "rowc.toml").cables[0].winch.stribeck_friction == 0.0
    f.write_text(text.replace("coulomb_friction = 0.03  # N·m at the motor (assumed)",
                              "coulomb_friction = 0.03\npulley_friction = 2.0"))  # fmt: skip
    with pytest.raises(ConfigError, match=r"winch.pulley_friction.*must be <= 1"):
        load_robot(f)


@pytest.mark.slow
def test_rowc_in_lockstep_with_each_winch_off_the_file():
    """rowc, seed 1: each winch's viscous and Coulomb friction 30-50 % off the file, a
    Stribeck term half the Coulomb one; the calibration accepted, every winch's Coulomb term
    within 15 % and viscous within 15 % of the simulated robot's (seeds 2 and 3 measured 8 and
    12 %: the 5 % of issue 68 is not reached on rowc, docs/friction.md), the Stribeck term
    within 25 %."""
    from cdprctl.experiments.friction_on_plant import friction_on_plant

    model = load_robot(CONFIG / "rowc.toml")
    truth = PlantErrors(1, 0.0, 0.0, friction=(0.3, 0.5), stribeck=0.5).apply(model)[0]
    cal = friction_on_plant(model, truth)
    assert cal.accepted, cal.reason
    for c, f in zip(truth.cables, cal.fits, strict=True):
        w = c.winch
        assert f.coulomb == pytest.approx(w.coulomb_friction, rel=0.15)
        assert f.viscous == pytest.approx(w.viscous_friction, rel=0.15)
        assert f.stribeck == pytest.approx(w.stribeck_friction, rel=0.25)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_rowc_with_load_cells_identifies_every_winch_within_5_percent(seed):
    """rowc with a load cell on every cable (config/rowc_load_cells.toml), each winch's
    viscous and Coulomb friction 30-50 % off the file: every winch fitted on its cell, its
    viscous and Coulomb terms within issue 68's 5 % of the simulated robot's. The projection
    left rowc 8-13 % off (docs/friction.md), and without the tension's rate term the cells
    gave 6-8 % on the viscous terms (seeds 1 and 2): either coming back fails here."""
    from cdprctl.experiments.friction_on_plant import friction_on_plant

    model = load_robot(CONFIG / "rowc_load_cells.toml")
    truth = PlantErrors(seed, 0.0, 0.0, friction=(0.3, 0.5), stribeck=0.5).apply(model)[0]
    cal = friction_on_plant(model, truth)
    assert cal.accepted, cal.reason
    for c, f in zip(truth.cables, cal.fits, strict=True):
        w = c.winch
        assert f.source == "load cell"
        assert f.coulomb == pytest.approx(w.coulomb_friction, rel=0.05)
        assert f.viscous == pytest.approx(w.viscous_friction, rel=0.05)


def test_the_status_and_the_start_up_say_which_friction_is_in_use(tmp_path):
    from cdprctl.calibration.calibration_record import load, save, stamped
    from cdprctl.calibration.friction import WinchFriction
    from cdprctl.calibration.friction_record import (
        friction_entry,
        friction_line,
        friction_summary,
        friction_terms,
    )

    model = load_robot(CONFIG / "rowc.toml")
    m = model.n_cables
    rec = stamped(model, "known-pose", theta_zero=[0.0] * m, drum_scale=[1.0] * m,
                  pose=[0.0] * 6, identities=[None] * m)  # fmt: skip
    save(rec, tmp_path)
    assert friction_summary(model, tmp_path)["source"] == "file"
    assert friction_terms(rec) is None and "the robot file's" in friction_line(rec)
    fits = [WinchFriction(4e-4 + 1e-5 * i, 0.02 + 0.001 * i, 0.01, 1.5e-4, (0.0,) * 4, None,
                          None, 1e-3, 2e-3, 100) for i in range(m)]  # fmt: skip
    fits[0].coulomb = -1e-4  # within its noise below zero: kept as 0
    rec.friction = friction_entry(model, fits, 120.0, True)
    save(rec, tmp_path)
    back = load(tmp_path)
    back.check(model)
    viscous, coulomb, stribeck, pulley = friction_terms(back)
    assert stribeck == [0.01] * m
    assert coulomb[0] == 0.0 and coulomb[3] == pytest.approx(0.023)
    assert pulley == [0.0] * m  # no pulley: the file's μ
    s = friction_summary(model, tmp_path)
    assert s["source"] == "calibrated" and s["viscous"] == viscous
    assert "Coulomb 0..0.027 N·m" in friction_line(back)


def test_the_printed_terms_are_the_recorded_ones(capsys):
    """A Stribeck term fitted below zero (within its noise) is printed as the record keeps
    it, 0, with the line that says so; the JSON and the record agree winch by winch."""
    import argparse
    import json

    from cdprctl.calibration.friction import WinchFriction
    from cdprctl.calibration.friction_procedure import FrictionCalibration
    from cdprctl.calibration.friction_record import friction_entry
    from cdprctl.commands.calibrate_friction import _report

    model = load_robot(CONFIG / "rowc.toml")
    m = model.n_cables
    fits = [WinchFriction(4e-4, 0.02, 0.01, 1.5e-4, (1e-5, 1e-3, 2e-3, 1e-5), None, None,
                          1e-3, 2e-3, 100, "no pulley") for _ in range(m)]  # fmt: skip
    fits[3].stribeck = -0.0021
    cal = FrictionCalibration(fits, [0.0] * 6, [[0.0] * 6], 120.0, True, "accepted")
    args = argparse.Namespace(json=True)
    assert _report(args, model, cal, None, None, None, print) == 0
    rows = json.loads(capsys.readouterr().out)["winches"]
    entry = friction_entry(model, fits, 120.0, True)
    for key in ("viscous", "coulomb", "stribeck"):
        assert [r[key] for r in rows] == entry[key]
    assert rows[3]["stribeck"] == 0.0
    assert rows[3]["clipped"].startswith("fitted Stribeck -0.0021 ± 0.002 below zero, kept as 0")
    assert all(r["clipped"] == "" for i, r in enumerate(rows) if i != 3)
    truth = PlantErrors(1, friction=(0.3, 0.5), stribeck=0.5).apply(model)[0]
    sim = argparse.Namespace(truth=truth)
    _report(argparse.Namespace(json=False), model, cal, None, None, sim, print)
    head, *out = capsys.readouterr().out.splitlines()
    assert "Stribeck 0 ± 0.002 N·m" in out[3] and "kept as 0" in out[3]
    assert "Stribeck 0.01 ± 0.002 N·m" in out[2] and "kept as 0" not in out[2]
    # what a newcomer asked of the text: what ± is, what the limit is of, which values are
    # the simulated robot's
    assert "± 1 σ of the fit (the samples' noise only" in head
    assert "against its limit (2x the torque's noise at rest)" in head
    w = truth.cables[3].winch
    assert f"[plant: viscous {w.viscous_friction:.4g}, Coulomb {w.coulomb_friction:.4g}" in out[3]
    assert "(fitted on the torques)" in out[3] and "(refused beyond 0.002)" in out[3]
