"""The load cells' tare (``cdprctl/calibration/load_cells.py``, `cdprctl load-cells zero`):
on the simulated robot with its platform on its stand, each cell's offset (seeded, a few N)
is found within 0.05 N; applied, the cells read the hanging platform's tensions; a platform
not at rest (readings spread beyond the accuracy) and a silent cell refuse the tare; the
command writes a simulated robot's record where a simulated robot's records go."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.calibration.load_cells import LoadCellError, apply, load, save, tare
from cdprctl.cli import main
from cdprctl.commands.load_cells import on_stand
from cdprctl.robot_file import load_robot
from sim_backend.network import LockStep

MODEL = load_robot(CONFIG / "rowc_load_cells.toml")
OFFSETS = np.random.default_rng(68).uniform(-5.0, 5.0, MODEL.n_cables)  # N


def _off(ls: LockStep) -> None:
    for c, node in ls.net.load_cells.items():
        node.offset = float(OFFSETS[c])


def test_tare_finds_each_offset_and_the_cells_then_read_the_tensions(tmp_path):
    with on_stand(MODEL) as ls:
        _off(ls)
        ls.driver.configure()
        record = tare(MODEL, ls.driver, 1.0, simulated=True, log=lambda s: None)
    assert record.samples == round(1.0 / MODEL.control.period)
    names = [c.name for c in MODEL.cables]
    found = np.array([record.offsets[n] for n in names])
    np.testing.assert_allclose(found, -OFFSETS, atol=0.05)
    save(record, tmp_path)
    back = load(tmp_path)
    assert back == record and back.simulated
    with LockStep(MODEL) as ls:  # hanging at home on its brakes: the cables loaded
        ls.plant.set_pose(MODEL.home.position, MODEL.home.rotation, None)
        _off(ls)
        ls.driver.configure()
        apply(back, MODEL, ls.driver)
        seen, tensions = [], []
        for _ in range(100):  # each reading is of the tension at the SYNC before
            tensions.append(ls.plant.tension.copy())
            ls.cycle(np.zeros(MODEL.n_cables))
            seen.append(ls.driver.states.tension.copy())
        np.testing.assert_allclose(np.mean(seen[1:], axis=0), np.mean(tensions[1:], axis=0),
                                   atol=0.05)  # fmt: skip


def test_refused_when_not_at_rest_or_a_cell_is_silent():
    with on_stand(MODEL) as ls:
        ls.net.load_cells[2].noise = 2.0  # N: beyond the 0.5 N accuracy (a swinging platform)
        ls.driver.configure()
        with pytest.raises(
            LoadCellError,
            match=r"load cell of cable 3 \(node 23\) read .* spread "
            r"beyond its accuracy 0.5 N: the platform is not at rest",
        ):
            tare(MODEL, ls.driver, 0.2, log=lambda s: None)
        ls.net.load_cells[2].noise = 0.1
        ls.net.load_cells[6].silent = True
        with pytest.raises(LoadCellError, match=r"load cell of cable 7 \(node 27\) gave no value"):
            tare(MODEL, ls.driver, 0.2, log=lambda s: None)


def test_a_record_of_another_robot_or_cells_is_refused(tmp_path):
    with on_stand(MODEL) as ls:
        ls.driver.configure()
        record = tare(MODEL, ls.driver, 0.1, log=lambda s: None)
    record.offsets.pop("8")
    with pytest.raises(LoadCellError, match=r"has offsets for cables"):
        record.check(MODEL)
    record.robot = "rowc"
    with pytest.raises(LoadCellError, match="is for robot 'rowc', not 'rowc-load-cells'"):
        record.check(MODEL)


def test_the_command_on_the_simulated_robot(tmp_path, capsys):
    args = ["load-cells", "zero", "--config", str(CONFIG / "rowc_load_cells.toml"), "--sim",
            "--seconds", "0.2", "--state-dir", str(tmp_path), "--json"]  # fmt: skip
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out["offsets"]) == {c.name for c in MODEL.cables}
    assert json.loads((tmp_path / "load_cells.json").read_text())["simulated"] is True
    # a robot without cells: one line with the fix
    assert main(["load-cells", "zero", "--config", str(CONFIG / "rowc.toml"), "--sim"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    fix = f"add [[sensors.load_cells]] to {CONFIG / 'rowc.toml'} (docs/config.md)"
    assert err == [f"cdprctl load-cells zero: error: rowc has no load cells: {fix}"]
    # a reading too short to average (or not a number) refused before a record is touched
    for seconds in ("0", "nan", "100"):
        assert main([*args[:-3], "--state-dir", str(tmp_path / "short"), "--seconds",
                     seconds]) == 2  # fmt: skip
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--seconds" in err[0] and "must be in [0.2, 60] s" in err[0]
    assert not (tmp_path / "short").exists()
