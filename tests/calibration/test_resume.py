"""Long procedures keep their work (docs/homing.md, "A stopped calibration keeps its samples";
docs/safety.md, "Brake test"): a calibration or brake test stopped midway by a fault keeps
what it measured in the state directory, and ``--resume`` goes on from it — lock-step on the
simulated robot, the fault injected mid-motion — to the result of a run never stopped;
refused in one line on another robot file, other options or a drive reset since."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import CONFIG
from test_homing import pose_error, robot_at, start_pose

from cdprctl.calibration.partial_session import (
    PartialSession,
    clear_latched_fault,
    load,
    path_of,
    save,
    timing_cause,
)
from cdprctl.calibration.procedure import self_calibrate
from cdprctl.calibration.progress import CalibrationStoppedError, Progress, check_reference
from cdprctl.cli import main
from cdprctl.robot_file import load_robot
from sim_backend.faults import FaultEvent, FaultInjector

ROWC = CONFIG / "rowc.toml"
# a simulated robot's bus as seen from another process: no drive is touched before the
# refusals, and the lock-step tests hand the command their own driver (``_drivers``)
BUS = ["--can-interface", "udp_multicast", "--can-channel", "239.74.163.9"]


def _fault_after(ls, line_start: str, kind: str = "drive_fault", cable: int = 2):
    """A log that injects ``kind`` on ``cable`` 0.5 s after the line starting ``line_start``
    (the sample at a pose: the move to the next one is then under way)."""
    lines: list[str] = []

    def log(line: str) -> None:
        lines.append(line)
        if line.startswith(line_start):
            FaultInjector([FaultEvent(ls.net.time + 0.5, kind, cable=cable, value=0x2310,
                                      duration=0.2)]).attach(ls.net)  # fmt: skip

    return log, lines


def _second_driver(ls, model):
    """A driver set up again on the same buses and drives (a command started again)."""
    from drivers.registry import create_driver

    return create_driver(model, period=ls.period, bus_overrides=ls.overrides, clock=ls.clock,
                         wait=ls.net.advance)  # fmt: skip


def _through_the_file(progress: Progress) -> Progress:
    return Progress.from_data(json.loads(json.dumps(progress.to_data())), progress.started)


def _stopped_self(ls, model, kind: str = "drive_fault") -> CalibrationStoppedError:
    ls.driver.configure()
    log, _ = _fault_after(ls, "  pose 4/", kind)
    with pytest.raises(CalibrationStoppedError) as exc:
        self_calibrate(model, ls.driver, log=log)
    ls.driver.shutdown()
    return exc.value


def test_self_stopped_midway_resumes_from_its_samples_and_finds_the_start():
    """rowc from a seeded unknown start (test_homing's seed 2): a drive fault on the move to
    pose 5 of 12 stops it with the start and 4 poses sampled; the drives set up again (not
    reset: the same encoder reference), the fault reset, it goes on from pose 5 and the record
    puts the platform where the plant is, within 1 mm / 1 mrad as an unstopped run."""
    model = load_robot(ROWC)
    p, R = start_pose(model, 2)
    with robot_at(model, p, R) as ls:
        stop = _stopped_self(ls, model)
        assert stop.at == "pose 5 of 12 (around the start)" and stop.progress.samples == 5
        assert stop.cause == ""  # a drive fault: nothing points at the machine's load
        assert "fault 0x2310" in str(stop)
        kept = _through_the_file(stop.progress)
        driver = _second_driver(ls, model)
        driver.configure()
        clear_latched_fault(driver, lambda _: None, "test")
        assert check_reference(model, driver, kept, list(ls.driver.identities), "F") == ""
        lines: list[str] = []
        rec, _ = self_calibrate(model, driver, log=lines.append, progress=kept)
        ls.driver = driver
        dp, dr = pose_error(model, rec, ls)
    assert any("resumed: 5 of 13 samples kept" in x for x in lines)
    assert not any(x.startswith(f"  pose {k}/") for x in lines for k in range(1, 5))
    assert rec.samples == 13 and kept.samples == 13
    assert all(np.array_equal(a, b) for a, b in zip(kept.theta[:5], stop.progress.theta[:5],
                                                   strict=True))  # fmt: skip
    assert dp < 1.0 and dr < 1.0, (dp, dr)


def test_a_resume_after_a_drive_reset_or_with_its_encoder_moved_is_refused(tmp_path):
    """A drive that went silent mid-move stops ``self`` (the line says what a feedback timeout
    can be: the machine's load or the drive); its drive then power-cycled: the incremental
    encoder's zero the samples were taken on is gone — refused in one line; and, should a
    driver not tell a reset, a motor reading more than 50 mm of cable from where the stop left
    it is (here, near the start where the counters began, the reset alone reads only a few
    mm off: the flag is what finds it)."""
    model = load_robot(ROWC)
    p, R = start_pose(model, 2)
    with robot_at(model, p, R) as ls:
        stop = _stopped_self(ls, model, "silent_drive")
        assert "no feedback for" in str(stop) and "feedback_timeout" in str(stop)
        assert stop.cause.startswith("a drive's feedback stopped longer than [drives] "
                                     "feedback_timeout with this process on time")  # fmt: skip
        assert 'docs/control.md, "Real time"' in stop.cause
        ls.net.power_cycle(2)
        ls.net.advance(0.01)
        driver = _second_driver(ls, model)
        driver.configure()
        ids = list(ls.driver.identities)
        kept = save(PartialSession("self", model.name, "h", {}, "f", "pose 1", 0,
                                   stop.progress.to_data(), "t", 0.0), tmp_path)  # fmt: skip
        progress = Progress.from_data(load(tmp_path, "self").data, 0.0)
        why = check_reference(model, driver, progress, ids, kept)
        assert why == (f"the drives of cables 3 were reset (power-up or NMT reset) since {kept} "
                       "was measured: their incremental encoders lost the zero its samples "
                       "were taken on: start over without --resume")  # fmt: skip
        # the refused resume's set-up wrote the drives' settings again: the next resume's
        # drives no longer show the reset, the partial session does (it let a second through)
        driver.reset_since_setup[:] = [False] * 8
        again = Progress.from_data(load(tmp_path, "self").data, 0.0)
        assert check_reference(model, driver, again, ids, kept).startswith(
            "the drives of cables 3 were reset (power-up or NMT reset) since ")
        assert "as an earlier --resume found" in check_reference(model, driver, again, ids, kept)
        # a driver that cannot tell, on a session that never saw it: the encoders' distance
        assert stop.progress.drives_reset == ""
        assert check_reference(model, driver, stop.progress, ids, "F") == ""
        ratio = model.cables[2].winch.drum_radius / model.cables[2].winch.gear_ratio
        assert stop.progress.stopped_theta is not None
        stop.progress.stopped_theta[2] += 0.06 / ratio  # 60 mm of cable
        why = check_reference(model, driver, stop.progress, ids, "F")
        assert why.startswith("the encoder of cable 3 reads ") and "(at most 50 mm)" in why
        driver.shutdown()


def test_a_timing_stop_names_the_machines_load_with_the_value_and_its_limit():
    from drivers.errors import DriverTimeoutError

    timeout = DriverTimeoutError("drive of cable index 2 (node 3): no TPDO for 32.0 ms of "
                                 "running cycles (8 reads; feedback_timeout 30 ms)", 2)  # fmt: skip
    why = timing_cause(timeout, 655, 21000)
    assert why.startswith("the machine was too busy: 655 of 21000 periods missed (3.12 %; a "
                          "quiet machine misses under 0.2 %: see docs/control.md")  # fmt: skip
    assert why.endswith("then resume")
    assert timing_cause(None, 30, 21000) == ""  # 0.14 %: not what stopped it
    assert timing_cause(None, 655, 21000).startswith("the machine was busy, and a late cycle "
                                                     "can cause this fault: 655 of 21000")
    assert timing_cause(None, 0, 21000) == ""


def _drivers(monkeypatch, ls, model, inject=None):
    """``cdprctl calibrate`` (and ``brake-test``) handed lock-step drivers: the first the
    LockStep's, each next one set up again on the same buses (a command started again);
    ``inject(net)`` when the first is handed."""
    import drivers

    handed: list = []

    def create_driver(*_a, **_k):
        d = ls.driver if not handed else _second_driver(ls, model)
        if not handed and inject is not None:
            inject(ls.net)
        handed.append(d)
        return d

    monkeypatch.setattr(drivers, "create_driver", create_driver)
    return handed


@pytest.fixture(scope="module")
def rowc_as_built():
    """rowc as built (non-reference anchors ±20 mm, drums ±1 %, seed 2), a start 4 cm from
    home, and its geometric calibration never stopped (12 poses: with 10, rowc's offset geometry
    predicts 5.3 mm of σ, over the 5 mm limit): the result and the simulated
    instant of each pose's sample line."""
    from cdprctl.calibration.geometry_plan import GeometryOptions
    from cdprctl.calibration.geometry_procedure import geometry_calibrate
    from cdprctl.model.calibration import reference_anchors
    from sim_backend.plant_errors import PlantErrors

    model = load_robot(ROWC)
    truth = PlantErrors(2, 0.02, 0.01, reference_anchors(model.calibration, model.anchors)
                        ).apply(model)[0]  # fmt: skip
    start = np.asarray(model.home.position) + np.array([0.02, 0.03, -0.02])
    at: dict[str, float] = {}
    with robot_at(model, start, model.home.rotation, truth) as ls:
        ls.driver.configure()

        def log(line: str) -> None:
            at[line.split(":")[0].strip()] = ls.net.time

        cal = geometry_calibrate(model, ls.driver, GeometryOptions(poses=12), log=log)
    return model, truth, start, cal, at


def test_a_geometric_calibration_stopped_at_a_pose_resumes_to_the_unstopped_result(
        rowc_as_built, tmp_path, monkeypatch, capsys):  # fmt: skip
    """`cdprctl calibrate ... geometry` on rowc as built, a drive fault on the move to pose 5
    of 11: exit 1, one line — where, the fault, 4 poses and the start's 13 samples kept in the
    state directory, the command that resumes; that command on the drives set up again: it goes
    on from pose 5 and identifies the same geometry as the run never stopped (the kept
    samples are those of the unstopped run: lock-step; the rest taken from where the fault
    left the platform), and removes the file."""
    model, truth, start, unstopped, at = rowc_as_built
    argv = ["calibrate", "--config", str(ROWC), "--state-dir", str(tmp_path), *BUS,
            "geometry", "--poses", "12", "--no-realtime", "--json"]  # fmt: skip
    partial = path_of(tmp_path, "geometry")
    with robot_at(model, start, model.home.rotation, truth) as ls:
        fault = FaultEvent(at["pose 4/11"] + 0.5, "drive_fault", cable=2, value=0x2310)
        handed = _drivers(monkeypatch, ls, model, FaultInjector([fault]).attach)
        assert main(argv) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert partial.exists() and len(handed) == 1
        assert err[-1].startswith("cdprctl calibrate: stopped at pose 5 of 11: the drives "
                                  "stopped: drive of cable index 2 (node 3) fault 0x2310")
        assert (f"; 4 poses and the start's 13 samples kept in {partial}; resume: cdprctl "
                f"calibrate --config {ROWC} --state-dir {tmp_path} --can-interface "
                "udp_multicast --can-channel 239.74.163.9 geometry --no-realtime --resume"
                ) in err[-1]  # fmt: skip
        assert "Traceback" not in "\n".join(err)
        assert main([*argv, "--resume"]) == 0
        out = capsys.readouterr()
    result = json.loads(out.out)
    assert "resuming the run stopped at pose 5 of 11 (4 poses and the start's 13 samples kept)" \
        in out.err  # fmt: skip
    assert "pose 4/11" not in out.err and "pose 5/11" in out.err
    assert not partial.exists() and "removed" in out.err
    r = unstopped.result
    assert result["accepted"] and unstopped.accepted
    assert result["poses"] == len(r.poses) == 13 + 11
    moved = np.linalg.norm(np.array(result["anchors"]) - r.anchors, axis=1)
    sigma = np.linalg.norm(r.std_anchors, axis=1)
    # the same geometry within a tenth of its own predicted σ (2.2-4.8 mm here) and 0.5 mm
    # (measured: 0.17 mm at most, the drums within 1.4e-5)
    assert np.all(moved < 0.1 * sigma + 1e-9) and np.max(moved) < 5e-4, (moved, sigma)
    assert np.max(np.abs(np.array(result["drum_scale"]) - r.drum_scale)) < 1e-4


def _partial_of(model, kind: str, options: dict, data: dict | None = None):
    from cdprctl.calibration.calibration_record import geometry_hash
    from cdprctl.calibration.partial_session import PartialSession

    return PartialSession(kind=kind, robot=model.name, geometry_hash=geometry_hash(model),
                          options=options, fault="f", stopped_at="pose 3 of 9", kept=3,
                          data=data or {}, time="2026-12-06T00:00:00+00:00", started=0.0,
                          simulated=True)  # fmt: skip


def test_a_resume_on_another_robot_file_or_with_other_options_is_refused_in_one_line(
        tmp_path, capsys):  # fmt: skip
    """Before any drive is touched, exit 2, one line naming what differs and the fix: other
    options (given, or from the robot file's [calibration]), another geometry, another
    robot, nothing stopped there; ``self`` likewise."""
    import dataclasses

    from cdprctl.calibration.geometry_plan import GeometryOptions
    from cdprctl.calibration.partial_session import save
    from cdprctl.calibration.procedure import SelfOptions, self_options

    model = load_robot(ROWC)
    state = tmp_path / "state"
    opt = dataclasses.asdict(GeometryOptions.of(model))
    filled = tmp_path / "filled.toml"
    filled.write_text(f'base = "{ROWC}"\n[calibration]\ngeometry_fill = 0.6\n')
    fix = "resume with the robot file and options it was started with, or start over " \
          "without --resume"  # fmt: skip
    where = path_of(state, "geometry")

    def refused(config, *extra, method="geometry"):
        argv = ["calibrate", "--config", str(config), "--state-dir", str(state), *BUS,
                method, "--resume", *extra]  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
        return err.strip()

    assert refused(ROWC) == (f"cdprctl calibrate: error: cannot resume: no stopped session to "
                             f"resume at {where} (run it without --resume: nothing stopped "
                             "there)")  # fmt: skip
    save(_partial_of(model, "geometry", opt), state)
    assert refused(ROWC, "--fill", "0.6").endswith(
        f"{where} was planned with fill = 0.8, this run's is 0.6 (--fill or [calibration] "
        f"geometry_fill): {fix}")  # fmt: skip
    assert "was planned with fill = 0.8, this run's is 0.6" in refused(filled)
    assert "was planned with poses = 25, this run's is 30 (--poses)" in refused(ROWC, "--poses",
                                                                                 "30")
    assert f"{where} is robot 'rowc''s, not 'caroca''s: {fix}" in refused(CONFIG / "caroca.toml")
    save(dataclasses.replace(_partial_of(model, "geometry", opt), geometry_hash="0" * 16), state)
    assert f"{where} was measured on another geometry (hash 0000000000000000, this robot " \
        "file's" in refused(ROWC)  # fmt: skip
    save(_partial_of(model, "self", self_options(SelfOptions())), state)
    assert "was planned with travel = 0.05, this run's is 0.04 (--travel)" in refused(
        ROWC, "--travel", "0.04", method="self")  # fmt: skip


def lock_steps_recorded(monkeypatch) -> list:
    """Every lock-step simulated robot a command makes from now, in order (a ``--sim``
    command makes its own: a test reaches its bus through this list)."""
    import sim_backend.network

    made: list = []

    class Recorded(sim_backend.network.LockStep):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            made.append(self)

    monkeypatch.setattr(sim_backend.network, "LockStep", Recorded)
    return made


def test_a_brake_test_stopped_after_cable_3_resumes_at_cable_4(tmp_path, monkeypatch, capsys):
    """`cdprctl brake-test --sim`, a drive fault while cable 4's brake is under its test
    torque: exit 1, one line — cables 1-3 kept, the command that resumes; on another robot
    file (another hold) that command is refused in one line; as given, it tests cables 4 to 8
    only, the record holds all eight (the first three those kept, dated from the first test:
    the interval counts from it) and the stopped test's file is removed."""
    from cdprctl.safety.brake_record import load
    from cdprctl.safety.brake_test import BrakeTest

    made = lock_steps_recorded(monkeypatch)
    one = BrakeTest._one

    def faulted_after_cable_3(self, c, name):
        result = one(self, c, name)
        if c == 2 and len(made) == 1:  # the first run only: 0.3 s into cable 4's ramp
            net = made[0].net
            FaultInjector([FaultEvent(net.time + 0.3, "drive_fault", cable=3)]).attach(net)
        return result

    monkeypatch.setattr(BrakeTest, "_one", faulted_after_cable_3)
    argv = ["brake-test", "--config", str(ROWC), "--sim", "--state-dir", str(tmp_path)]
    partial = path_of(tmp_path, "brake-test")
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and partial.exists(), err
    assert err[0].startswith("cdprctl brake-test: stopped at cable 4 of 8: the drives stopped: "
                             "drive of cable index 3 (node 4) fault")  # fmt: skip
    assert err[0].endswith(f"; cables 1, 2, 3 (3 of 8) kept in {partial}; resume: cdprctl "
                           f"brake-test --config {ROWC} --state-dir {tmp_path} --sim --resume")
    kept = json.loads(partial.read_text())
    other = tmp_path / "longer.toml"
    other.write_text(f'base = "{ROWC}"\n[safety]\nbrake_test_hold = 2.0\n')
    assert main(["brake-test", "--config", str(other), "--sim", "--state-dir", str(tmp_path),
                 "--resume"]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "was planned with hold = 1.0, this run's is 2.0 ([safety] " \
        "brake_test_hold)" in err[0]  # fmt: skip
    assert main([*argv, "--resume"]) == 0
    out = capsys.readouterr().out
    tested = [line for line in out.splitlines() if line.startswith("  cable ")]
    assert [line.split(" (index")[0] for line in tested] == [f"  cable {i}" for i in range(4, 9)]
    assert "resumed: cables 1, 2, 3 kept from the stopped test" in out
    record = load(tmp_path)
    assert record.passed and [c.cable for c in record.cables] == [str(i) for i in range(1, 9)]
    assert [c.__dict__ for c in record.cables[:3]] == kept["data"]["cables"]
    assert record.unix_time == kept["started"]
    assert not partial.exists()
