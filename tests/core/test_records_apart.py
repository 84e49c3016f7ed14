"""A simulation never writes where a real robot's records live, and a state directory that
cannot take a record is refused before anything moves (docs/safety.md, "Where the record
goes"; cdprctl/core/state_dir.py). The real root is moved to a temporary directory for the tests
that write a real robot's record; /var/lib/cdprctl itself is compared before and after."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest
from conftest import CONFIG

import cdprctl.core.state_dir as state_dir
import cdprctl.safety.brake_record as brake_record
from cdprctl.calibration.calibration_record import CalibrationError
from cdprctl.calibration.calibration_record import load as load_calibration
from cdprctl.calibration.startup_checks import load_record
from cdprctl.cli import main
from cdprctl.robot_file import load_robot
from cdprctl.safety.brake_record import BrakeTestError, check_due
from cdprctl.safety.brake_record import load as load_brakes
from drivers.simulated import simulated_identities, simulated_robot

ROWC = str(CONFIG / "rowc.toml")
REAL = b'{"format": 1, "robot": "rowc", "passed": true, "note": "the real robot\'s"}\n'


def snapshot(root: Path) -> dict[str, tuple[int, bytes]]:
    """Every file under ``root``: (mtime ns, contents)."""
    if not root.exists():
        return {}
    return {str(f): (f.stat().st_mtime_ns, f.read_bytes()) for f in root.rglob("*") if f.is_file()}


@pytest.fixture
def homes(tmp_path, monkeypatch):
    """(the real robots' root, the simulated robots' root), both temporary; a real record of
    rowc's brake test and calibration in the real one."""
    real_root = tmp_path / "var-lib-cdprctl"
    (real_root / "rowc").mkdir(parents=True)
    for name in ("brake_test.json", "calibration.json"):
        (real_root / "rowc" / name).write_bytes(REAL)
    monkeypatch.setattr(state_dir, "REAL_ROOT", real_root)
    monkeypatch.setenv("XDG_STATE_HOME", str(tmp_path / "state-home"))
    return real_root, tmp_path / "state-home" / "cdprctl" / "simulated"


def test_a_simulated_brake_test_leaves_the_real_records_and_says_where_it_wrote(homes, capsys):
    real_root, sim_root = homes
    before, var_before = snapshot(real_root), snapshot(Path("/var/lib/cdprctl"))
    assert main(["brake-test", "--config", ROWC, "--sim", "--weak-brake", "6"]) == 3
    out = capsys.readouterr().out
    assert snapshot(real_root) == before and snapshot(Path("/var/lib/cdprctl")) == var_before
    record = load_brakes(sim_root / "rowc")
    assert record.simulated and not record.passed
    assert f"a simulated robot: the record goes to {sim_root / 'rowc'}" in out
    assert f"record: {sim_root / 'rowc' / 'brake_test.json'}" in out


@pytest.mark.parametrize("where", ["real-root", "holds-real"])
def test_a_simulation_refuses_a_real_robots_directory_before_anything_moves(
    homes, tmp_path, capsys, where
):
    real_root, _ = homes
    target = real_root / "rowc"
    if where == "holds-real":
        target = tmp_path / "elsewhere"
        target.mkdir()
        (target / "calibration.json").write_bytes(REAL)
    before = snapshot(target)
    code = main(["brake-test", "--config", ROWC, "--sim", "--state-dir", str(target)])
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert code == 4 and len(lines) == 1, cap.err
    says = "where real robots' records live" if where == "real-root" else (
        "holds a real robot's calibration.json")  # fmt: skip
    assert says in lines[0] and "leave --state-dir out" in lines[0], lines
    assert "configuring the drives" not in cap.out  # refused before the drives are touched
    assert snapshot(target) == before


def test_a_simulated_record_may_replace_a_simulated_one(tmp_path, capsys):
    state = tmp_path / "s"
    for _ in range(2):
        assert main(["brake-test", "--config", ROWC, "--sim", "--state-dir", str(state)]) == 0
    assert load_brakes(state).simulated


def test_calibrate_on_udp_multicast_refuses_a_real_record_before_the_bus_opens(tmp_path,
                                                                               capsys):  # fmt: skip
    """udp_multicast reaches no wire: only a simulated robot answers there, so calibrate's
    record is a simulated one and a directory holding a real record is refused — before
    the bus is opened (no drive needs to answer for this)."""
    state = tmp_path / "real"
    state.mkdir()
    (state / "brake_test.json").write_bytes(REAL)
    code = main(["calibrate", "--config", ROWC, "--state-dir", str(state), "--can-interface",
                 "udp_multicast", "--can-channel", "239.74.163.9", "known-pose"])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 4 and len(err) == 1 and "holds a real robot's brake_test.json" in err[0]


@pytest.mark.parametrize("argv", [
    ["brake-test", "--config", ROWC, "--sim"],
    ["calibrate", "--config", ROWC, "--can-interface", "socketcan", "--can-channel", "can9",
     "known-pose"],
    ["calibrate", "--config", ROWC, "--can-interface", "socketcan", "--can-channel", "can9",
     "geometry", "--out", "OUT"],
])  # fmt: skip
def test_an_unwritable_state_directory_is_refused_before_motion_in_one_line(tmp_path, capsys,
                                                                            argv):  # fmt: skip
    """A directory that cannot be created (under /proc: even root cannot) is refused with
    exit 4 and one line naming it, why, its nearest existing parent's owner and the fix,
    before any drive is configured (a real robot on can9, which does not exist, would fail
    later, at its bus)."""
    argv = [str(tmp_path / "robot.toml") if a == "OUT" else a for a in argv]
    code = main([*argv[:3], "--state-dir", "/proc/nope/rowc", *argv[3:]])
    cap = capsys.readouterr()
    lines = cap.err.strip().splitlines()
    assert code == 4 and len(lines) == 1, cap.err
    assert "cannot write the state directory /proc/nope/rowc (No such file or directory; " \
        "/proc: owner root" in lines[0]
    assert "give --state-dir DIR" in lines[0] and "Traceback" not in cap.err
    assert "configuring the drives" not in cap.out + cap.err


def test_a_write_that_fails_after_the_motion_keeps_the_result_as_json(tmp_path, monkeypatch,
                                                                       capsys):  # fmt: skip
    def full_disk(path, fmt, record):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(brake_record, "write_json", full_disk)
    code = main(["brake-test", "--config", ROWC, "--sim", "--state-dir", str(tmp_path)])
    cap = capsys.readouterr()
    assert code == 4 and "Traceback" not in cap.err
    err = [line for line in cap.err.splitlines() if line.strip()]
    assert len(err) == 1 and "could not be written to" in err[0]
    assert "No space left on device" in err[0]
    kept = json.loads(cap.out.strip().splitlines()[-1])
    assert kept["simulated"] and len(kept["cables"]) == 8 and kept["passed"]


def test_the_simulated_robot_rule():
    model = load_robot(ROWC)
    assert simulated_robot(model, {"interface": "udp_multicast", "channel": "239.0.0.1"})
    assert simulated_robot(model, {"interface": "virtual"})
    assert not simulated_robot(model, {"interface": "socketcan", "channel": "can0"})
    sim = [{"vendor_id": 0, "serial": 0x53494D00 + n} for n in range(1, 9)]
    assert simulated_identities(sim)
    assert not simulated_identities([*sim[:7], {"vendor_id": 0xFB, "serial": 0x53494D08}])
    assert not simulated_identities([*sim[:7], None]) and not simulated_identities([])
    assert not simulated_identities([*sim[:7], {"vendor_id": 0, "serial": 0x12345608}])

    class Configured:
        identities = sim

    assert simulated_robot(model, {"interface": "socketcan", "channel": "vcan0"}, Configured())


def test_a_real_robot_never_takes_a_simulated_record(tmp_path, capsys):
    """The simulated record in a real robot's start-up: refused (calibration and brake test);
    a simulated robot (across processes) takes its own."""
    model = load_robot(ROWC)
    assert main(["brake-test", "--config", ROWC, "--sim", "--state-dir", str(tmp_path)]) == 0
    now = load_brakes(tmp_path).unix_time + 1.0
    with pytest.raises(BrakeTestError, match="simulated robot"):
        check_due(model, tmp_path, now)
    assert check_due(model, tmp_path, now, simulated=True).simulated
    from test_homing import _record

    from cdprctl.calibration.calibration_record import save

    record = _record(model)
    record.simulated = True
    save(record, tmp_path)
    assert load_calibration(tmp_path).simulated
    with pytest.raises(CalibrationError, match="taken on a simulated robot"):
        load_record(model, tmp_path)
    assert load_record(model, tmp_path, simulated=True).simulated


def test_the_simulated_default_is_the_users_own(monkeypatch):
    monkeypatch.delenv("XDG_STATE_HOME", raising=False)
    monkeypatch.setenv("HOME", "/home/someone")
    assert state_dir.simulated_state_dir("rowc") == Path(
        "/home/someone/.local/state/cdprctl/simulated/rowc")
    assert state_dir.state_dir_for("rowc", None, False) == Path("/var/lib/cdprctl/rowc")
    assert state_dir.state_dir_for("rowc", "/srv/x", False) == Path("/srv/x")
    assert not os.fspath(state_dir.state_dir_for("rowc", None, True)).startswith("/var/lib")


@pytest.mark.parametrize("argv", [
    ["run", "--config", ROWC, "--duration", "1"],
    ["drives", "scan", "--config", ROWC],
    ["brake-test", "--config", ROWC],
    ["calibrate", "--config", ROWC, "known-pose"],
])  # fmt: skip
def test_the_in_process_bus_without_sim_is_named_not_searched(argv, capsys):
    """rowc's file puts its drives on python-can's in-process `virtual` bus: without --sim
    nothing can answer there; one line says what it is and what to do (it said "0 of 8 ...
    powered? wired?" after a second of listening)."""
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "in-process 'virtual' bus: no drive and no other process can answer there;" in err[0]
    assert "cdprctl sim --config" in err[0] and "udp_multicast" in err[0]
    # drives scan takes no --sim: it is not offered one
    assert ("use --sim" in err[0]) == (argv[0] != "drives"), err[0]
