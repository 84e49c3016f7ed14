"""The holding brakes' test (docs/safety.md, "Brake test"): the simulated brake against its
closed-form stick-slip law, the test torque's rule against the robot files' numbers, the
procedure in lock-step (every brake holds; a worn one alone fails, its torque off at once),
0x60FE against drives whose dictionaries their vendors wrote, the record and `cdprctl run`'s
refusal of a real robot whose last brake test is missing, failed or too old."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.calibration.calibration_record import geometry_hash
from cdprctl.calibration.calibration_record import save as save_calibration
from cdprctl.cli import main
from cdprctl.model import ConfigError
from cdprctl.robot_file import load_robot
from cdprctl.safety.brake_record import (
    BrakeTestError,
    BrakeTestRecord,
    CableResult,
    check_drives,
    check_due,
    load,
    save,
)
from cdprctl.safety.brake_test import BrakeTest, BrakeTestFailedError, brake_test_torques
from sim_backend.network import LockStep
from sim_backend.plant import CdprPlant

ROWC = CONFIG / "rowc.toml"


def quiet(_: str) -> None:
    pass


def at_rest_plant(model):
    """rowc's plant at home, brakes closed, settled (every drum at rest)."""
    plant = CdprPlant(model)
    plant.set_pose(model.home.position, model.home.rotation, None)
    plant.step(0.2)
    return plant


# -- the simulated brake ------------------------------------------------------------------------
def test_a_closed_brake_holds_up_to_its_torque_then_slips_and_sticks_again():
    """Karnopp's stick-slip friction on the drum of cable index 0: a motor torque that keeps
    the torque on the brake within its holding torque moves nothing; 20 % beyond, the drum
    accelerates at (excess) / J in the pay-out direction — compared with the closed form over
    the first millisecond, while the tension has barely changed — and once the motor's
    torque is off the drum stops and stays."""
    model = load_robot(ROWC)
    plant = at_rest_plant(model)
    r, J = plant.drum_ratio[0], plant.rotor_inertia[0]
    load = r * plant.tension[0]  # N·m the cable puts on the brake
    hold = 1.5
    plant.brake_hold[0] = hold
    theta0 = plant.theta.copy()
    plant.motor_torque[0] = -(hold - load) * 0.99  # the brake sees 99 % of its holding torque
    plant.step(0.1)
    assert plant.theta[0] == theta0[0] and plant.theta_dot[0] == 0.0
    excess = 0.2 * hold
    plant.motor_torque[0] = -(hold - load) - excess
    n, dt = 5, plant.opt.physics_dt
    plant.step(n * dt)
    # viscous friction over 1 ms is below 0.1 % of the excess here; the tension's change too.
    # Semi-implicit Euler (velocity first): after n steps at constant a, v = a n dt and
    # θ = a dt² n (n + 1) / 2 (½ a t² as dt → 0)
    a = -excess / J
    assert plant.theta_dot[0] == pytest.approx(a * n * dt, rel=0.02)
    assert plant.theta[0] - theta0[0] == pytest.approx(a * dt**2 * n * (n + 1) / 2, rel=0.02)
    plant.motor_torque[0] = 0.0  # the brake now sees the cable alone: it stops the drum
    plant.step(0.05)
    assert plant.theta_dot[0] == 0.0
    stopped = plant.theta[0]
    plant.step(0.1)
    assert plant.theta[0] == stopped
    np.testing.assert_array_equal(plant.theta[1:], theta0[1:])  # the other drums held


def test_the_default_brakes_hold_five_times_the_motors_limit_a_worn_one_less_than_the_test():
    model = load_robot(ROWC)
    plant = CdprPlant(model)
    np.testing.assert_allclose(plant.brake_hold, 5 * 2.6)  # 5 × rowc's torque_limit, N·m
    plant.weaken_brake(5)
    assert plant.brake_hold[5] == pytest.approx(0.6 * 200.0 * 0.045 / 5.0)  # 1.08 N·m
    torque, _ = brake_test_torques(model)
    assert plant.brake_hold[5] < torque[5]


# -- the test torque ----------------------------------------------------------------------------
def test_the_test_torque_is_1_3_times_the_worst_case_load_capped_at_the_drives_limit(tmp_path):
    """rowc: 1.3 × 200 N × 0.045 m / 5 = 2.34 N·m, below its 2.6 N·m limit; CoGiRo's 1.3 ×
    its worst-case load is beyond its drives' 30 N·m: capped there, and said; a fixed
    `brake_test_torque` replaces the rule, still capped."""
    torque, capped = brake_test_torques(load_robot(ROWC))
    np.testing.assert_allclose(torque, 2.34)
    assert not capped.any()
    torque, capped = brake_test_torques(load_robot(CONFIG / "cogiro.toml"))
    np.testing.assert_allclose(torque, 30.0)
    assert capped.all()
    fixed = tmp_path / "fixed.toml"
    fixed.write_text(f'base = "{ROWC}"\n[safety]\nbrake_test_torque = 2.0\n')
    np.testing.assert_allclose(brake_test_torques(load_robot(fixed))[0], 2.0)
    fixed.write_text(f'base = "{ROWC}"\n[safety]\nbrake_test_torque = 9.0\n')
    torque, capped = brake_test_torques(load_robot(fixed))
    np.testing.assert_allclose(torque, 2.6)
    assert capped.all()


@pytest.mark.parametrize(
    ("line", "says"),
    [
        ("brake_test_max_counts = 0", "safety.brake_test_max_counts = 0 counts must be >= 1"),
        ("brake_test_max_counts = 2.5", "safety.brake_test_max_counts = 2.5 counts must be an "
                                        "integer"),
        ("brake_test_interval = 10", "safety.brake_test_interval = 10 s must be >= 60"),
        ("brake_test_torque_factor = 0.9", "safety.brake_test_torque_factor = 0.9 must be >= 1"),
        ("brake_test_torque = -1", "safety.brake_test_torque = -1 N·m must be > 0"),
        ("brake_test_hold = 0", "safety.brake_test_hold = 0 s must be >= 0.1"),
        ("brake_tset_hold = 1", "brake_tset_hold"),
    ],
)  # fmt: skip
def test_a_bad_safety_section_is_refused_naming_the_field_value_unit_and_rule(
    tmp_path, line, says
):
    bad = tmp_path / "bad.toml"
    bad.write_text(f'base = "{ROWC}"\n[safety]\n{line}\n')
    with pytest.raises(ConfigError) as exc:
        load_robot(bad)
    assert any(says in e for e in exc.value.errors), exc.value.errors


# -- the procedure, lock-step ----------------------------------------------------------------------
def test_every_brake_holds_its_test_torque():
    """rowc in lock-step: each drive pushed 2.34 N·m in the pay-out direction against its
    closed brake (its torque actual says so), no motor moved a count, the platform did not
    move, and afterwards every drive is disabled with its brake given back (0x60FE bit 0
    clear) and closed by the drive itself."""
    model = load_robot(ROWC)
    with LockStep(model) as ls:
        ls.driver.configure()
        position = ls.plant.position.copy()
        record = BrakeTest(model, ls.driver, quiet).run()
        assert record.passed and record.robot == "rowc" and record.max_counts == 4
        for c in record.cables:
            assert c.passed and c.motion == 0.0 and not c.capped and not c.stopped_early
            assert c.torque == pytest.approx(2.34)
            assert c.applied == pytest.approx(2.34, rel=1e-3)
        assert np.linalg.norm(ls.plant.position - position) < 1e-6
        nodes = [node for table in ls.net.nodes for node in table.values()]
        assert len(nodes) == 8
        for node in nodes:
            assert node.od[(0x60FE, 1)] & 1 == 0
            assert node.axis.state.name == "SWITCH_ON_DISABLED"
        assert ls.plant.brake.all()


def test_a_worn_brake_alone_fails_and_its_torque_comes_off_at_once():
    """Cable index 5's brake worn (it holds 1.08 N·m, the test asks 2.34 + the cable's load):
    it alone fails; the test stopped as its motion passed 4 counts, so the drum slipped only
    a few counts more and the platform moved less than 0.1 mm; the others pass."""
    model = load_robot(ROWC)
    with LockStep(model) as ls:
        ls.plant.weaken_brake(5)
        ls.driver.configure()
        position = ls.plant.position.copy()
        record = BrakeTest(model, ls.driver, quiet).run()
        assert not record.passed
        assert [c.passed for c in record.cables] == [i != 5 for i in range(8)]
        worn = record.cables[5]
        assert worn.stopped_early and 4 < worn.counts < 12
        assert worn.motion == pytest.approx(worn.counts * 2 * math.pi / 65536)
        assert np.linalg.norm(ls.plant.position - position) < 1e-4
        assert ls.plant.theta_dot[5] == 0.0  # held again once the torque was off


def test_a_drive_that_does_not_push_fails_the_test_instead_of_passing_it():
    """A drive whose torque stays below the test torque (here 0x6072 limits it to half)
    applies no test at all: its brake is not passed, and the line says what the drive
    applied."""
    model = load_robot(ROWC)
    lines: list[str] = []
    with LockStep(model) as ls:
        ls.driver.configure()
        ls.driver.sdo.write(2, 0x6072, 0, 500, 2, 1.0)  # per mille of the rated torque
        record = BrakeTest(model, ls.driver, lines.append).run()
    assert [c.passed for c in record.cables] == [i != 2 for i in range(8)]
    assert record.cables[2].applied < 0.6 * 2.34
    assert any("FAIL: the drive applied only" in line for line in lines)


def test_a_drive_fault_during_the_test_stops_it_with_the_drives_disabled():
    """A drive fault mid-test: BrakeTestFailedError naming it; every drive disabled (the
    faulted one in FAULT), every brake closed."""
    from sim_backend.faults import FaultEvent, FaultInjector

    model = load_robot(ROWC)
    with LockStep(model) as ls:
        ls.driver.configure()
        FaultInjector([FaultEvent(ls.net.time + 1.0, "drive_fault", cable=1)]).attach(ls.net)
        with pytest.raises(BrakeTestFailedError, match="the drives stopped"):
            BrakeTest(model, ls.driver, quiet).run()
        assert ls.plant.brake.all()
        assert np.all(ls.plant.motor_torque == 0.0)


# -- 0x60FE on the vendors' dictionaries ------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "mask"), [("maxon_epos4_0x6050.eds", False), ("elmo_gold_Elmo.eds", True)]
)
def test_set_brake_is_written_as_each_vendors_dictionary_has_it(name, mask):
    """0x60FE bit 0 on drives served from their vendors' EDS by the `canopen` package: with
    a bit mask (Elmo: 0x60FE:02) the mask's bit 0 is set too; without one (maxon EPOS4) only
    sub-index 1 — and releasing clears the bit again, the other outputs kept."""
    from test_vendor_drives import bring_up, rowc

    model = rowc("csp")
    network, drives, driver = bring_up(model, [name])
    try:
        driver.configure()
        d = drives[3]
        d.node.sdo[0x60FE][1].raw = 0x00010000  # another output the brake must leave alone
        driver.command_brake(3, True, 1.0)
        assert d.value(0x60FE, 1) == 0x00010001
        assert (d.value(0x60FE, 2) == 1) if mask else d.value(0x60FE, 2) is None
        assert d.value(0x60FE, 1) is not None and drives[2].value(0x60FE, 1) == 0
        driver.command_brake(3, False, 1.0)
        assert d.value(0x60FE, 1) == 0x00010000
    finally:
        driver.shutdown()
        network.disconnect()


def test_the_odrive_driver_says_it_cannot_command_a_brake(tmp_path, capsys):
    config = tmp_path / "odrive.toml"
    config.write_text(f'base = "{ROWC}"\n[drives]\ndriver = "odrive"\nmode = "cst"\n')
    code = main(["brake-test", "--config", str(config), "--sim", "--state-dir",
                 str(tmp_path / "s")])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 1
    assert "cdprctl brake-test: failed: the odrive driver cannot command a holding brake" in err
    assert "Traceback" not in err and not (tmp_path / "s" / "brake_test.json").exists()


# -- the command line ----------------------------------------------------------------------------
def test_brake_test_sim_json_and_weak_brake(tmp_path, capsys):
    """`cdprctl brake-test --sim --json`: every cable passes, exit 0, the record in the state
    directory; `--weak-brake 6`: cable 6 (index 5) alone fails, exit 3; the JSON as documented."""
    state = str(tmp_path / "s")
    assert main(["brake-test", "--config", str(ROWC), "--sim", "--json", "--state-dir",
                 state]) == 0  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert out["passed"] and len(out["cables"]) == 8
    assert set(out["cables"][0]) >= {"cable", "passed", "torque", "motion"}
    assert load(tmp_path / "s").passed
    assert main(["brake-test", "--config", str(ROWC), "--sim", "--json", "--state-dir", state,
                 "--weak-brake", "6"]) == 3  # fmt: skip
    out = json.loads(capsys.readouterr().out)
    assert [c["passed"] for c in out["cables"]] == [i != 5 for i in range(8)]
    assert not load(tmp_path / "s").passed


@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (["--weak-brake", "5"], "--weak-brake 5: only with --sim"),
        (["--sim", "--weak-brake", "9"], "--weak-brake 9: not a cable of rowc (its cables: 1, 2,"),
        (["--sim", "--weak-brake", "0"], "--weak-brake 0: not a cable of rowc"),
    ],
)
def test_brake_test_refuses_a_bad_option_in_one_line(tmp_path, capsys, extra, says):
    code = main(["brake-test", "--config", str(ROWC), "--state-dir", str(tmp_path), *extra])
    err = capsys.readouterr().err
    assert code == 2 and says in err and len(err.strip().splitlines()) == 1


# -- the record and `cdprctl run` ----------------------------------------------------------------
def passed_record(model, unix_time: float, passed: bool = True) -> BrakeTestRecord:
    cables = [CableResult(c.name, passed, 2.34, 2.34, 0.0, 0.0, False) for c in model.cables]
    return BrakeTestRecord(model.name, "2026-12-04T08:00:00+00:00", unix_time, passed, 4, cables)


def test_an_enable_needs_a_passed_brake_test_younger_than_the_interval(tmp_path):
    model = load_robot(ROWC)
    now = 1_800_000_000.0
    with pytest.raises(BrakeTestError, match="no brake test record at"):
        check_due(model, tmp_path, now)
    save(passed_record(model, now - 3600.0), tmp_path)
    assert check_due(model, tmp_path, now).passed  # 1 h old
    save(passed_record(model, now - 8 * 3600.0 - 1.0), tmp_path)
    with pytest.raises(BrakeTestError, match=r"8\.0 h old, beyond \[safety\] brake_test_int"):
        check_due(model, tmp_path, now)
    save(passed_record(model, now - 60.0, passed=False), tmp_path)
    with pytest.raises(BrakeTestError, match="failed on cable"):
        check_due(model, tmp_path, now)
    save(passed_record(model, now + 600.0), tmp_path)
    with pytest.raises(BrakeTestError, match="after this machine's clock"):
        check_due(model, tmp_path, now)
    simulated = dataclasses.replace(passed_record(model, now - 60.0), simulated=True)
    save(simulated, tmp_path)
    with pytest.raises(BrakeTestError, match="was run on the simulated robot, not on these"):
        check_due(model, tmp_path, now)
    other = dataclasses.replace(passed_record(model, now), robot="caroca")
    save(other, tmp_path)
    with pytest.raises(BrakeTestError, match="of robot 'caroca'"):
        check_due(model, tmp_path, now)
    (tmp_path / "brake_test.json").write_text("{not json")
    with pytest.raises(BrakeTestError, match="unreadable"):
        check_due(model, tmp_path, now)


def test_a_brake_test_is_of_the_drives_tested():
    """Once configured, the drives' identities (0x1018) against the test's: an exchanged
    drive refuses; an identity either side does not know does not."""
    model = load_robot(ROWC)
    names = [c.name for c in model.cables]
    ident = [{"vendor_id": 0, "serial": 0x53494D01 + i} for i in range(8)]
    record = dataclasses.replace(passed_record(model, 0.0), identities=ident)
    check_drives(record, list(ident), names)
    check_drives(record, [None] * 8, names)
    swapped = list(ident)
    swapped[3] = {"vendor_id": 0, "serial": 7}
    with pytest.raises(BrakeTestError, match="the drive of cable 4 is not the one whose brake "
                       "was tested"):  # fmt: skip
        check_drives(record, swapped, names)


def test_a_sim_brake_test_is_recorded_as_simulated(tmp_path, capsys):
    """`brake-test --sim` writes its record marked simulated: the state directory of a real
    robot of the same name would otherwise take it for its brakes' test."""
    assert main(["brake-test", "--config", str(ROWC), "--sim", "--state-dir",
                 str(tmp_path)]) == 0  # fmt: skip
    assert load(tmp_path).simulated
    with pytest.raises(BrakeTestError, match="simulated robot"):
        check_due(load_robot(ROWC), tmp_path, load(tmp_path).unix_time + 1.0)
    assert "(index 5)" in capsys.readouterr().out


def test_run_refuses_a_real_robot_without_a_brake_test_in_one_line(tmp_path, capsys):
    """A robot that does not assume home, calibrated, but with no brake test on record:
    `cdprctl run` refuses before any drive is configured, exit 4, naming the command."""
    from test_homing import _record

    config = tmp_path / "real.toml"
    config.write_text(f'base = "{ROWC}"\n[drives]\nassume_home_at_start = false\n')
    model = load_robot(config)
    state = tmp_path / "state"
    record = _record(model)
    assert record.geometry_hash == geometry_hash(model)
    save_calibration(record, state)
    args = ["run", "--config", str(config), "--state-dir", str(state), "--no-realtime",
            "--duration", "1", "--can-interface", "udp_multicast", "--can-channel",
            "239.74.163.9", "--can-option", "port=43119"]  # fmt: skip
    assert main(args) == 4
    err = capsys.readouterr().err
    assert "refusing to enable the drives: no brake test record at" in err
    # the command to run, with the bus options this run was given
    assert (f"cdprctl brake-test --config {config} --state-dir {state} --can-interface "
            "udp_multicast --can-channel 239.74.163.9 --can-option port=43119") in err  # fmt: skip
