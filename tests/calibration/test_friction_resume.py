"""A friction calibration stopped midway keeps its round trips and ``--resume`` goes on from
them (docs/friction.md, "A stopped calibration"): ``cdprctl calibrate friction --sim`` on rowc
in lock-step, a drive fault injected on a round trip's way out."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import CONFIG
from test_resume import lock_steps_recorded

from cdprctl.calibration.friction_progress import FrictionProgress
from cdprctl.calibration.partial_session import path_of
from cdprctl.cli import main
from cdprctl.robot_file import load_robot
from sim_backend.faults import FaultEvent, FaultInjector

ROWC = CONFIG / "rowc.toml"


def test_the_progress_reads_back_to_the_same_bits():
    rng = np.random.default_rng(5)
    p = FrictionProgress(rng.normal(size=6), [rng.normal(size=6) for _ in range(3)],
                         rng.uniform(size=8),
                         [rng.normal(size=(20, 34)), rng.normal(size=(30, 34))], done=2, moved=12.5,
                         stopped_theta=rng.normal(size=8), started=1.7e9)  # fmt: skip
    back = FrictionProgress.from_data(json.loads(json.dumps(p.to_data())), p.started)
    for a, b in ((p.start, back.start), (p.noise, back.noise), (p.rows, back.rows),
                 (p.stopped_theta, back.stopped_theta), *zip(p.ends, back.ends, strict=True)):
        assert np.array_equal(a, b)  # fmt: skip
    assert (back.done, back.moved, back.samples) == (2, 12.5, 50)


def _faulted_on_leg(monkeypatch, leg: int) -> list:
    """The calibration's lock-step robots, recorded; in the first, a drive fault on cable 3
    0.3 s into its ``leg``-th way (1-based: way out of round trip ``(leg + 1) // 2``)."""
    from cdprctl.calibration import friction_procedure

    made = lock_steps_recorded(monkeypatch)
    original, legs = friction_procedure._leg, [0]

    def leg_with_a_fault(ses, *a, **k):
        legs[0] += 1
        if legs[0] == leg and len(made) == 1:
            net = made[0].net
            FaultInjector([FaultEvent(net.time + 0.3, "drive_fault", cable=2,
                                      value=0x2310)]).attach(net)  # fmt: skip
        return original(ses, *a, **k)

    monkeypatch.setattr(friction_procedure, "_leg", leg_with_a_fault)
    return made


@pytest.mark.slow
def test_a_friction_calibration_stopped_midway_resumes_from_its_round_trips(
        tmp_path, monkeypatch, capsys):  # fmt: skip
    """A drive fault on the way out of round trip 4 of 9 (line 2): exit 1 and one line —
    where, the fault, 3 round trips kept in the state directory, the command that resumes;
    with another --travel that command is refused in one line; as given, it goes on from round
    trip 4 (line 1 not moved again), fits on the kept samples and the new ones (every winch
    within 15 % of the simulated robot's friction, the file's here: the unstopped run's test
    in test_friction.py) and removes the file. Nothing is written where a real robot's records
    go (--sim)."""
    model = load_robot(ROWC)
    made = _faulted_on_leg(monkeypatch, leg=7)
    argv = ["calibrate", "--config", str(ROWC), "--state-dir", str(tmp_path), "friction",
            "--sim", "--travel", "0.2"]  # fmt: skip
    partial = path_of(tmp_path, "friction")
    assert main(argv) == 1
    out, err = capsys.readouterr()
    err_lines = err.strip().splitlines()
    assert len(err_lines) == 1 and partial.exists(), err
    assert err_lines[0].startswith("cdprctl calibrate: stopped at round trip 4 of 9 (line 2, "
                                   "0.03 m/s): the drives stopped: drive of cable index 2")
    assert err_lines[0].endswith(
        f"; 3 round trips ({json.loads(partial.read_text())['data']['rows_shape'][0]} samples) "
        f"kept in {partial}; resume: cdprctl calibrate --config {ROWC} --state-dir {tmp_path} "
        "friction --sim --travel 0.2 --resume")  # fmt: skip
    assert "line 1/3" in out and "Traceback" not in err
    kept = json.loads(partial.read_text())["data"]

    assert main([*argv[:-1], "0.3", "--resume"]) == 2
    refused = capsys.readouterr().err.strip().splitlines()
    assert len(refused) == 1 and "was planned with travel = 0.2, this run's is 0.3 (--travel)" \
        in refused[0]  # fmt: skip

    assert main([*argv, "--resume", "--json"]) == 0
    out, err = capsys.readouterr()
    assert len(made) == 3  # the stopped run's robot, the refused one's, the resumed one's
    assert "resuming the run stopped at round trip 4 of 9" in err
    assert f"resumed: 3 of 9 round trips kept ({kept['rows_shape'][0]} samples)" in err
    assert "line 1/3" not in err and "line 2/3" in err and "line 3/3" in err
    assert not partial.exists() and "removed" in err
    result = json.loads(out)
    assert result["accepted"], result["reason"]
    for c, w in zip(model.cables, result["winches"], strict=True):
        assert w["viscous"] == pytest.approx(c.winch.viscous_friction, rel=0.15)
        assert w["coulomb"] == pytest.approx(c.winch.coulomb_friction, rel=0.15)


def test_the_motion_is_fitted_apart_on_either_side_of_a_resume():
    """A resumed run's clock restarts (lock-step) or jumps (another process): the kept samples
    and the new ones are fitted apart (``motion_of``), not as one motion through the jump —
    here two runs at 2 rad/s from different angles, the second's clock from 0 again."""
    from cdprctl.calibration.friction_procedure import motion_of

    period = 0.004
    t1 = 100.0 + period * np.arange(200)
    t2 = period * np.arange(200)
    theta = np.r_[1.0 + 2.0 * (t1 - t1[0]), 5.0 + 2.0 * t2][:, None]
    w, a = motion_of(theta, np.r_[t1, t2], period)
    assert np.allclose(w, 2.0, atol=1e-9) and np.allclose(a, 0.0, atol=1e-6)


def test_a_resume_at_another_control_rate_is_refused(tmp_path, capsys):
    """The fit's speeds come from the period the samples were taken at: a run stopped at
    rowc's 250 Hz is not resumed by rowc_1khz.toml (the same robot, its geometry's hash the
    same), in one line naming the rate."""
    from cdprctl.calibration.friction_procedure import FrictionOptions
    from cdprctl.calibration.partial_session import save
    from cdprctl.commands.calibrate_friction import KIND, plan_of
    from cdprctl.commands.resume import new_partial

    model = load_robot(ROWC)
    args = type("Args", (), {"sim": True, "plant_errors": None, "pulley_friction": None})()
    plan = plan_of(args, model, FrictionOptions(), np.zeros(model.n_cables))
    progress = FrictionProgress(np.zeros(6), [np.ones(6)], np.ones(8), [np.zeros((3, 34))],
                                done=1)  # fmt: skip
    save(new_partial(KIND, model, plan, "a fault", "round trip 2 of 9", 1, progress.to_data(),
                     1.7e9, True, []), tmp_path)  # fmt: skip
    argv = ["calibrate", "--config", str(CONFIG / "rowc_1khz.toml"), "--state-dir",
            str(tmp_path), "friction", "--sim", "--resume"]  # fmt: skip
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "was planned with period = 0.004, this run's is 0.001 ([control] " \
        "rate)" in err[0], err  # fmt: skip


def test_the_resume_command_is_the_one_the_user_typed(monkeypatch):
    """A stop's resume command starts as the user started it (``.venv/bin/cdprctl``: a bare
    ``cdprctl`` is not on the PATH of the README's install, and a pasted line failed)."""
    import argparse

    from cdprctl.commands.resume import resume_command

    args = argparse.Namespace(config="config/rowc.toml", state_dir=None)
    monkeypatch.setattr("sys.argv", [".venv/bin/cdprctl", "calibrate"])
    assert resume_command("cdprctl calibrate", args, {}, "friction") == \
        ".venv/bin/cdprctl calibrate --config config/rowc.toml friction --resume"  # fmt: skip
    monkeypatch.setattr("sys.argv", ["/usr/lib/python3/pytest"])
    assert resume_command("cdprctl brake-test", args, {}, "").startswith("cdprctl brake-test ")
