"""Homing and calibration (docs/homing.md): the record, the simulated robot started at an
unknown pose with incremental encoders, ``known-pose`` and ``self`` in lock-step against the
plant's truth, and the start-up's refusals."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import CONFIG, in_torque_mode

from cdprctl.calibration.calibration_record import (
    CalibrationError,
    geometry_hash,
    load,
    record_path,
    save,
)
from cdprctl.calibration.identify import Identification, Samples
from cdprctl.calibration.procedure import SelfOptions, known_pose, sample_poses, self_calibrate
from cdprctl.calibration.session import CalibrationFailedError
from cdprctl.calibration.startup_checks import check_drives, load_record, offsets
from cdprctl.cli import main
from cdprctl.control.cycle.estimator import Estimator
from cdprctl.control.lifecycle.manager import ControllerManager
from cdprctl.core.numerics import compliance_of, unstretched_lengths
from cdprctl.core.rotation import exp_so3, log_so3, matrix_to_rpy
from cdprctl.geometry.kinematics import KinematicsData, inverse_kinematics
from cdprctl.robot_file import load_robot, parse_robot
from cdprctl.robot_file.loader import read_merged
from cdprctl.tda.hold import equilibrium_tensions
from sim_backend.network import LockStep
from sim_backend.plant import CdprPlant


def start_pose(model, seed):
    """A seeded pose within 10 cm and 5° of home, inside the workspace box."""
    rng = np.random.default_rng(seed)
    home = np.asarray(model.home.position, float)
    ws = model.workspace
    for _ in range(100):
        d = rng.normal(size=3)
        d *= rng.uniform(0.0, 0.1) / np.linalg.norm(d)
        if np.all(home + d >= ws.position_min) and np.all(home + d <= ws.position_max):
            break
    a = rng.normal(size=3)
    a *= rng.uniform(0.0, np.radians(5.0)) / np.linalg.norm(a)
    return home + d, exp_so3(a) @ model.home.rotation


def robot_at(model, position, R, plant_model=None):
    plant = CdprPlant(plant_model or model)
    plant.set_pose(position, R, None)
    return LockStep(model, plant=plant, encoders="incremental")


def estimated_pose(model, record, theta, tensions):
    """The estimator's pose from ``theta`` with the record applied (converged from home)."""
    e = Estimator(model)
    e.apply_calibration(*offsets(record))
    for k in range(30):
        e.update(0.01 * k, theta, tensions)
    return e.position.copy(), e.rotation.copy()


def pose_error(model, record, ls):
    """mm and mrad between the calibrated estimate and the plant's truth, now."""
    ls.net.advance(0.05)
    st = ls.driver.read(ls.net.time)
    p, R = estimated_pose(model, record, st.position.copy(), ls.plant.tension.copy())
    dp = np.linalg.norm(p - ls.plant.position) * 1e3
    dr = np.linalg.norm(log_so3(R @ ls.plant.R.T)) * 1e3
    return dp, dr


def test_record_is_written_atomically_and_checked(tmp_path):
    model = load_robot(CONFIG / "rowc.toml")
    with pytest.raises(CalibrationError, match="no calibration record at"):
        load_record(model, tmp_path)
    rec = _record(model)
    path = save(rec, tmp_path)
    assert path == record_path(tmp_path) and not list(tmp_path.glob(".calibration-*"))
    assert load_record(model, tmp_path) == rec
    moved = dataclasses.replace(
        model, cables=(dataclasses.replace(model.cables[0], anchor=np.array([0.0, 0.25, 0.01])),
                       *model.cables[1:]),
    )  # fmt: skip
    assert geometry_hash(moved) != geometry_hash(model)
    with pytest.raises(CalibrationError, match="geometry changed"):
        load_record(moved, tmp_path)
    path.write_text("{not json")
    with pytest.raises(CalibrationError, match="unreadable"):
        load(tmp_path)
    bad = dataclasses.replace(rec, theta_zero=[float("nan")] * 8)
    save(bad, tmp_path)
    with pytest.raises(CalibrationError, match="theta_zero"):
        load_record(model, tmp_path)


def _record(model):
    from cdprctl.calibration.calibration_record import CalibrationRecord

    return CalibrationRecord(
        robot=model.name, method="known-pose", time="2026-12-01T00:00:00+00:00",
        geometry_hash=geometry_hash(model), encoders="incremental",
        theta_zero=[0.0] * model.n_cables, drum_scale=[1.0] * model.n_cables,
        pose=[*model.home.position, 0.0, 0.0, 0.0], identities=[None] * model.n_cables,
    )  # fmt: skip


def test_incremental_encoders_start_at_zero_and_restart_at_a_reset():
    model = load_robot(CONFIG / "rowc.toml")
    p, R = start_pose(model, 1)
    with robot_at(model, p, R) as ls:
        ls.driver.configure()
        assert ls.driver.reset_since_setup == [True] * 8  # fresh drives: 0x1017 at its default
        st = ls.driver.read(ls.net.time)
        assert np.all(np.abs(st.position) < 1e-3)  # zero wherever the motors stand
        assert np.max(np.abs(ls.plant.theta)) > 1.0  # though the cables are far from home
        ls.net.power_cycle(2)
        ls.net.advance(0.01)
        ls.driver.shutdown()
    with robot_at(model, p, R) as ls:
        ls.driver.configure()
        ls.driver.shutdown()
        # the same drives set up again (a new LockStep: its bus, its drives): all fresh
        assert all(ls.driver.reset_since_setup)


def test_known_pose_recovers_the_offsets_exactly():
    """The platform at a known pose (not home; incremental counters at zero there): the
    record makes the estimator give that pose to within micrometres."""
    model = load_robot(CONFIG / "rowc.toml")
    p, R = start_pose(model, 4)
    with robot_at(model, p, R) as ls:
        ls.driver.configure()
        rec = known_pose(model, ls.driver, np.r_[p, matrix_to_rpy(R)], log=lambda s: None)
        dp, dr = pose_error(model, rec, ls)
    assert rec.method == "known-pose" and rec.identities[0]["serial"] == 0x53494D01
    assert dp < 0.02 and dr < 0.05, (dp, dr)


@pytest.mark.parametrize(
    ("robot", "seed"), [("rowc", 2), ("rowc", 3), ("caroca", 1), ("caroca", 2)]
)
def test_self_calibration_finds_an_unknown_start(robot, seed):
    """From a seeded unknown pose within 10 cm / 5° of home, the drives only: the calibrated
    estimate within 1 mm and 1 mrad of the plant's truth (the 20-seed table:
    tools/homing_table.py, docs/homing.md)."""
    model = load_robot(CONFIG / f"{robot}.toml")
    p, R = start_pose(model, seed)
    with robot_at(model, p, R) as ls:
        ls.driver.configure()
        rec, ident = self_calibrate(model, ls.driver, log=lambda s: None)
        dp, dr = pose_error(model, rec, ls)
        # it brought the platform back where it found it (within 3 mm: the damped cables
        # yield by their static tension error over their stiffness, and rowc's platform
        # hangs on 37 N/m of geometric stiffness: 2.3 mm on seed 2), and disabled the drives
        assert np.linalg.norm(ls.plant.position - p) < 3e-3
        assert ls.plant.brake.all()
    # within 1 mm and 1 mrad, but CAROCA's height to ~2 mm: its anchors share one plane, so
    # the lengths see the height only at second order and the tensions decide it, to one
    # count of the drives' torque (2 N); the record predicts it (σ_z ~1.7 mm)
    assert dp < (1.0 if robot == "rowc" else 2.5) and dr < 1.0, (dp, dr, rec.std)
    assert dp < 3.0 * np.linalg.norm(rec.std[:3]) * 1e3 + 0.2
    assert rec.samples == 13 and ident.residual_rms < 20e-6 and ident.condition < 1e4
    assert np.linalg.norm(np.array(rec.pose[:3]) - p) < 3e-3  # sample 0: after the settle


def test_identification_against_synthetic_samples():
    """The least squares alone, on samples computed from the model's own kinematics and cable
    law (noise-free): the start pose to within micrometres, drum scales too when fitted."""
    model = load_robot(CONFIG / "caroca.toml")
    law = compliance_of(model.cables)
    ratio = np.array([c.winch.drum_radius / c.winch.gear_ratio for c in model.cables])
    kin = KinematicsData(model)
    x0 = np.r_[np.asarray(model.home.position) + np.array([0.03, -0.05, 0.04]), 0.02, -0.03, 0.01]
    scale = 1.0 + np.linspace(-0.004, 0.004, 8)
    guess = sample_poses(model, SelfOptions())
    deltas = guess - guess[0]
    th, ts = [], []
    for d in deltas:
        x = x0 + d
        inverse_kinematics(model, kin, x[:3], exp_so3(x[3:]) @ model.home.rotation)
        t = equilibrium_tensions(model, kin)
        th.append(-unstretched_lengths(law, kin.length, t) / (ratio * scale))
        ts.append(t)
    th = np.array(th) - th[0]
    for fit in (False, True):
        s = Samples(th, np.array(ts), guess)
        got = Identification(model, fit).solve(s)
        err = got.poses[0] - x0
        if fit:
            assert np.max(np.abs(err[:3])) < 1e-4 and np.max(np.abs(err[3:])) < 1e-4, err
            assert np.max(np.abs(got.drum_scale - scale)) < 2e-4
        else:  # the scale errors biased into the pose, and visible in the residuals
            assert got.residual_rms > 1e-5


@pytest.mark.parametrize("robot_file", ["rowc.toml", "caroca.toml", "cogiro.toml"])
def test_the_weights_are_the_residuals_inverse_standard_deviations(robot_file):
    """Least squares is only as good as its weights: each weighted residual should have about
    unit spread under the noise the weights assume. A tension error of σ_t on every cable
    moves the equilibrium residual ``W δt`` by σ_t·√((W Wᵀ)_jj) in component j (computed
    here from W at home); weighted, that is at most 1 (Cauchy-Schwarz: forces ≤ √m σ_t,
    moments ≤ √m σ_t times the largest attachment radius) and, for a weight of the right
    scale, not far below — a moment weighted 1/σ·reach instead of 1/(σ·reach) is off by
    reach² (rowc: 44×). A length closure's noise is its σ exactly."""
    model = load_robot(CONFIG / robot_file)
    ident = Identification(model, fit_drum_scales=True)
    kin = KinematicsData(model)
    inverse_kinematics(model, kin, model.home.position, model.home.rotation)
    W = np.array(kin.W)
    spread = ident.w.tension * np.sqrt(np.diag(W @ W.T))  # N, N·m
    weighted = ident.force_weight * spread
    assert np.all(weighted <= 1.0 + 1e-12), weighted
    assert np.all(weighted >= 0.05), weighted
    # the same through the residuals: tensions off by seeded noise of σ_t, at the true poses
    rng = np.random.default_rng(39)
    theta = np.zeros((2, model.n_cables))
    t0 = equilibrium_tensions(model, kin)
    draws = []
    for _ in range(400):
        noisy = t0 + rng.normal(scale=ident.w.tension, size=(2, model.n_cables))
        guess = np.zeros((2, 6))
        guess[:, :3] = model.home.position
        z = np.concatenate([guess.ravel(), np.ones(model.n_cables)])  # poses, drum scales
        r = ident.residuals(z, Samples(theta, noisy, guess))
        draws.append(r[-6:])  # sample 1's equilibrium residual, weighted
    rms = np.sqrt(np.mean(np.square(draws), axis=0))
    np.testing.assert_allclose(rms, weighted, rtol=0.15)


def test_self_calibration_refuses_torque_mode():
    model = in_torque_mode(load_robot(CONFIG / "cogiro.toml"))
    with LockStep(model) as ls:
        ls.driver.configure()
        with pytest.raises(CalibrationFailedError, match="csp"):
            self_calibrate(model, ls.driver, log=lambda s: None)


def test_start_up_refuses_a_reset_drive(tmp_path):
    """A record taken, then a drive power-cycled: the start-up refuses before the estimate
    (the manager's hook, as the daemon uses it), naming the cable."""
    model = load_robot(CONFIG / "rowc.toml")
    p, R = start_pose(model, 5)
    with robot_at(model, p, R) as ls:
        ls.driver.configure()
        rec = known_pose(model, ls.driver, np.r_[p, matrix_to_rpy(R)], log=lambda s: None)
        save(rec, tmp_path)
        ls.driver.shutdown()
        driver2 = _driver_on(ls, model)
        mgr = ControllerManager(model, driver2)
        mgr.startup(calibration=lambda d: (check_drives(model, rec, d), offsets(rec))[1])
        assert np.linalg.norm(mgr.controller.estimator.position - ls.plant.position) < 1e-4
        driver2.shutdown()
        ls.net.power_cycle(6)
        ls.net.advance(0.01)
        driver3 = _driver_on(ls, model)
        with pytest.raises(CalibrationError, match="cables 7 were reset"):
            ControllerManager(model, driver3).startup(
                calibration=lambda d: (check_drives(model, rec, d), offsets(rec))[1]
            )
        driver3.shutdown()


def _driver_on(ls, model):
    from drivers import create_driver

    return create_driver(
        model, period=ls.period, clock=ls.clock, wait=ls.net.advance, bus_overrides=ls.overrides
    )


def test_run_refuses_without_a_record_and_with_a_stale_one(tmp_path, capsys):
    """`cdprctl run` on a robot that does not assume home: no record, or one from another
    geometry → refused before any drive is enabled, exit code 4, saying how to calibrate."""
    base = CONFIG / "rowc.toml"
    config = tmp_path / "real.toml"
    config.write_text(f'base = "{base}"\n[drives]\nassume_home_at_start = false\n')
    args = ["run", "--config", str(config), "--state-dir", str(tmp_path / "state"),
            "--no-realtime", "--duration", "1", "--can-interface", "udp_multicast",
            "--can-channel", "239.74.163.9", "--can-option", "port=43119"]  # fmt: skip
    assert main(args) == 4
    err = capsys.readouterr().err
    assert "refusing to enable the drives: no calibration record at" in err
    assert "cdprctl calibrate --config" in err and "known-pose" in err
    model = load_robot(config)
    stale = dataclasses.replace(_record(model), geometry_hash="0123456789abcdef")
    save(stale, tmp_path / "state")
    assert main(args) == 4
    assert "geometry changed" in capsys.readouterr().err
    data = json.loads(record_path(tmp_path / "state").read_text())
    assert data["format"] == 1


def test_self_refuses_a_record_the_geometry_would_bias():
    """rowc whose anchors are up to 5 mm off and drums 0.5 % (seeded): before, `self`
    accepted such records predicting ~1 mm while 7-21 mm off (docs/homing.md); the length
    closures are 3.6x what the drives' resolution explains, and the record is refused, naming
    why and what to do; without the errors the same start is accepted."""
    from sim_backend.plant_errors import PlantErrors

    model = load_robot(CONFIG / "rowc.toml")
    p, R = start_pose(model, 1)
    with robot_at(model, p, R, PlantErrors(1).apply(model)[0]) as ls:
        ls.driver.configure()
        with pytest.raises(CalibrationFailedError, match="the length residuals are") as exc:
            self_calibrate(model, ls.driver, log=lambda s: None)
        assert "cdprctl calibrate --config F geometry --out" in str(exc.value)
        assert exc.value.record.notes["residuals_over_noise"] > 2.0
        dp, _ = pose_error(model, exc.value.record, ls)
        assert dp > 3.0  # mm: what accepting it would have cost
    with robot_at(model, p, R) as ls:
        ls.driver.configure()
        rec, _ = self_calibrate(model, ls.driver, log=lambda s: None)
        assert rec.notes["residuals_over_noise"] < 1.2


def test_a_move_stops_on_a_tension_that_persists_beyond_its_stop_not_on_a_spike():
    """``Session.move_stops``, the rule of every calibration move: a tension beyond where a
    move stops, and further that way than at the move's start, stops it once it has stayed
    there ``STOP_PERSISTS`` (a single-cycle spike does not); one already beyond at the start
    and going no further does not; ``stopped_by`` names the cable and the limit."""

    from cdprctl.calibration.session import Session

    model = load_robot(CONFIG / "rowc.toml")
    m = model.n_cables
    driver = SimpleNamespace(period=0.004, states=SimpleNamespace(torque=np.zeros(m),
                                                                   velocity=np.zeros(m)))
    ses = Session(model, driver, lambda _: None)  # type: ignore[arg-type]
    ses.t_stop_low, ses.t_stop_high = np.full(m, 50.0), np.full(m, 500.0)
    ses.states = driver.states

    def tensions(t: np.ndarray) -> None:
        driver.states.torque[:] = t * ses.ratio

    base = np.full(m, 100.0)
    tensions(base)
    ses.begin_move()
    spike = base.copy()
    spike[2] = 600.0
    for _ in range(3):  # spikes of one cycle
        tensions(spike)
        assert not ses.move_stops()
        tensions(base)
        assert not ses.move_stops()
    cycles = 0
    tensions(spike)
    while not ses.move_stops():
        cycles += 1
        assert cycles < 100
    assert cycles + 1 == round(Session.STOP_PERSISTS / driver.period)
    assert ses.stopped_by == (f"cable {model.cables[2].name} at 600.0 N (it stops a move "
                              "beyond 500.0 N)")  # fmt: skip
    low = base.copy()
    low[5] = 40.0
    tensions(low)
    ses.begin_move()  # already below 50 N at the start, going no lower
    assert ses.stopped_by == "" and not any(ses.move_stops() for _ in range(20))
    low[5] = 38.0  # 2 N lower than at the start
    tensions(low)
    assert sum(not ses.move_stops() for _ in range(20)) == cycles
    assert ses.stopped_by == (f"cable {model.cables[5].name} at 38.0 N (it stops a move "
                              "beyond 50.0 N)")  # fmt: skip


class _StallingDriver:
    """A driver on a clock of its own: reads, writes and waits take no time but the one
    ``stall`` says (where, cycle index, s held up), as a process that stalled there."""

    def __init__(self, m: int, stall: tuple[str, int, float]):
        from drivers.vocabulary import Lifecycle

        self.period, self.now, self.stall = 0.004, 100.0, stall
        self.lifecycle, self.error = Lifecycle.ACTIVE, ""
        self.states = SimpleNamespace(torque=np.zeros(m), position=np.zeros(m),
                                      velocity=np.zeros(m))
        self.writes: list[float] = []

    def _held(self, where: str) -> None:
        cycle = len(self.writes) - (where == "write")
        if self.stall[:2] == (where, cycle):
            self.now += self.stall[2]

    def clock(self) -> float:
        return self.now

    def read(self, now: float):
        self._held("read")
        return self.states

    def write(self, now: float, torques, targets=None) -> None:
        self.writes.append(self.now)  # when the drives get it
        self._held("write")  # its frames gone: the process held up after them

    def wait(self, dt: float) -> None:
        self.now += dt
        self._held("wait")  # after the write of that cycle: the next one's index


@pytest.mark.parametrize("where", ["read", "write", "wait"])
def test_a_stalled_calibration_cycle_skips_what_it_missed_and_moves_on_by_the_extrapolation(
        where):  # fmt: skip
    """``Session.run`` after a stall of 0.1 s (this process held up in a read, a write or
    past its wait): no burst of catch-up cycles (their SYNCs bunched made following-error faults
    across processes), the ramp's fraction moves on once by the drives' target extrapolation
    (50 ms: 12 periods) and waits out the rest — never back — and the last cycle still gets
    the fraction 1; the skipped periods counted."""
    from cdprctl.calibration.session import Session

    model = load_robot(CONFIG / "rowc.toml")
    for at in (40, 98, 99):
        d = _StallingDriver(model.n_cables, (where, at, 0.1005))
        ses = Session(model, d, lambda _: None)  # type: ignore[arg-type]
        d.states.torque[:] = 100.0 * ses.ratio  # N in every cable: inside its limits
        fractions: list[float] = []
        ses.run(0.4, fractions.append)  # 100 periods
        steps = np.round(np.diff(fractions) * 100).astype(int)
        gaps = np.diff(d.writes)
        assert fractions[-1] == 1.0 and np.all(steps >= 1), (at, fractions)
        assert np.all(gaps > 0.5 * d.period)  # never two cycles in a burst
        # each target as far along as the drives went since the last: one period, or after
        # a stall as many as they extrapolated (12) and one — the end of the ramp aside
        went = np.minimum(np.round(gaps / d.period).astype(int), 13)
        done = np.array(fractions[1:]) == 1.0
        assert np.all((steps == went) | done), (at, list(zip(steps, went, strict=True)))
        if at == 40:
            assert ses.missed_periods in (24, 25) and sorted(steps)[-2:] == [1, 13]
            assert len(fractions) == 100 - 12


def test_a_record_that_does_not_fit_the_robot_is_refused_saying_what(tmp_path):
    """``CalibrationRecord.check`` and ``load``: another robot's name (either side of this
    one's), a list of the wrong length, a drum scale at or beyond 0.9-1.1 (exclusive), a file
    of another format or not a JSON object: each refused in words; the default state
    directory is systemd's; the hash is 16 hex digits, blind to a float's last digits (below
    a nanometre) and not to a nanometre."""
    from cdprctl.calibration.calibration_record import default_state_dir

    model = load_robot(CONFIG / "rowc.toml")
    rec = _record(model)
    rec.check(model)
    assert default_state_dir("rowc") == Path("/var/lib/cdprctl/rowc")
    for robot in ("aaa", "zzz"):
        with pytest.raises(CalibrationError, match=f"the record is for robot '{robot}'"):
            dataclasses.replace(rec, robot=robot).check(model)
    for n in (7, 9):
        with pytest.raises(CalibrationError, match=r"theta_zero: .* is not 8 finite numbers"):
            dataclasses.replace(rec, theta_zero=[0.0] * n).check(model)
    for scales, ok in (([1.09] * 8, True), ([0.91] * 8, True), ([1.1] * 8, False),
                       ([0.9] * 8, False), ([0.5] * 8, False), ([0.0] * 8, False),
                       ([1.2] * 8, False)):  # fmt: skip
        r = dataclasses.replace(rec, drum_scale=scales)
        if ok:
            r.check(model)
        else:
            with pytest.raises(CalibrationError, match=r"outside \(0.9, 1.1\)"):
                r.check(model)
    for text in ('{"format": 0}', '{"format": 2}', "[1, 2]", "{}"):
        record_path(tmp_path).write_text(text)
        with pytest.raises(CalibrationError, match="not a calibration record of format 1"):
            load(tmp_path)
    record_path(tmp_path).write_text('{"format": 1, "robot": "rowc"}')  # fields missing
    with pytest.raises(CalibrationError, match=r"missing .* required positional argument"):
        load(tmp_path)
    assert rec.samples == 1  # a record made without samples: the one pose it was held at
    h = geometry_hash(model)
    assert len(h) == 16 and int(h, 16) >= 0

    def off(field: str, dx: float):
        c0 = model.cables[0]
        moved = getattr(c0, field) + np.array([dx, 0.0, 0.0])
        return dataclasses.replace(model, cables=(dataclasses.replace(c0, **{field: moved}),
                                                  *model.cables[1:]))  # fmt: skip

    for field in ("anchor", "attachment"):
        assert geometry_hash(off(field, 3e-10)) == h and geometry_hash(off(field, 2e-9)) != h


def test_a_record_is_saved_into_a_new_state_directory_and_a_failed_write_leaves_nothing(
        tmp_path):  # fmt: skip
    """``save`` makes the state directory with its parents (a first calibration on a robot
    PC); a write that fails leaves the old record and no temporary file, and says why."""
    model = load_robot(CONFIG / "rowc.toml")
    rec = _record(model)
    deep = tmp_path / "var" / "lib" / "cdprctl" / "rowc"
    assert save(rec, deep) == record_path(deep) and load(deep) == rec
    newer = dataclasses.replace(rec, time="2026-12-02T00:00:00+00:00")
    with pytest.MonkeyPatch.context() as mp:
        def refused(*_a, **_k):
            raise OSError(28, "No space left on device")

        mp.setattr("cdprctl.core.state_file.os.replace", refused)
        with pytest.raises(OSError, match="No space left"):
            save(newer, deep)
    assert load(deep) == rec and sorted(p.name for p in deep.iterdir()) == ["calibration.json"]


def test_the_geometry_hash_of_a_shipped_robot_is_what_records_in_the_field_hold():
    """The hash every record on a robot PC was written with: a change of how it is computed
    (the fields, their order, their rounding) refuses every one of them after an upgrade
    ("geometry changed": recalibrate). Change these values only on purpose, and say so.
    rowc's changed on purpose with its geometry (issue 67: its crossed pairs offset): a record
    of the layout before is refused, as it must be; that layout still hashes as it did."""
    assert geometry_hash(load_robot(CONFIG / "rowc.toml")) == "f2d538e9beddfa41"
    data = read_merged(CONFIG / "rowc.toml")
    for cable in data["cables"]:  # the layout before: anchors at the frame's corners, ...
        a, b = cable["anchor"], cable["attachment"]
        a[0], a[2] = (0.0 if a[0] < 1.5 else 3.0), (0.0 if a[2] < 0.7 else 1.4)
        b[2] = 0.1 if b[2] > 0.0 else -0.1  # ... attachments at the body's corners
    assert geometry_hash(parse_robot(data, "rowc before")) == "501d6d292634f352"
    assert geometry_hash(load_robot(CONFIG / "caroca.toml")) == "65afdc6cefd6ee88"
