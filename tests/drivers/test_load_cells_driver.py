"""The load cells' read side and set-up (``drivers/load_cells.py``) with the CiA 402 driver in
lock-step against the simulated cells (``sim_backend/drives/load_cell.py``): each cable's
measured tension is the plant's within the cell's noise, a dead cell reads NaN once past its
timeout, a cell whose TPDO is mapped otherwise is mapped by SDO (or refused with
``pdo_mapping = 'static'``), and the decoding of each data type against ``struct``."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest
from conftest import CONFIG

from cdprctl.robot_file import load_robot
from drivers.cia402.protocol import HB_PRE_OPERATIONAL
from drivers.errors import DriverInitializationError
from drivers.load_cells import cells_kernel
from sim_backend.faults import FaultEvent, FaultInjector
from sim_backend.network import LockStep

MODEL = load_robot(CONFIG / "rowc_load_cells.toml")


@pytest.fixture
def rig():
    ls = LockStep(MODEL)
    ls.plant.set_pose(MODEL.home.position, MODEL.home.rotation, None)
    try:
        yield ls
    finally:
        ls.close()


def _cycles(ls: LockStep, n: int) -> None:
    for _ in range(n):
        ls.cycle(np.zeros(MODEL.n_cables))


def test_tensions_follow_the_plant(rig):
    ls = rig
    ls.driver.configure()
    _cycles(ls, 5)
    st = ls.driver.states
    # a cycle late: the TPDO answers the SYNC of the last write
    np.testing.assert_allclose(st.tension, ls.plant.tension, atol=0.5)  # noise 0.1 N, 5 σ
    assert np.all(st.tension_age <= 2 * ls.period)
    assert ls.driver.stats.frames_ignored == 0


def test_a_dead_cell_reads_nan_after_its_timeout_and_an_offset_shows(rig):
    ls = rig
    ls.driver.configure()
    t0 = ls.net.time + 0.01
    events = [FaultEvent(t0, "load_cell_dead", cable=2),
              FaultEvent(t0, "load_cell_offset", cable=5, value=7.0)]  # fmt: skip
    FaultInjector(events).attach(ls.net)
    _cycles(ls, 6)
    st = ls.driver.states
    assert st.tension[5] - ls.plant.tension[5] == pytest.approx(7.0, abs=0.5)
    timeout = MODEL.sensors.load_cells[2].timeout
    seen = []
    for _ in range(int(0.1 / ls.period)):
        _cycles(ls, 1)
        seen.append((ls.net.time, bool(math.isnan(st.tension[2]))))
    first = next(t for t, dead in seen if dead)
    assert 0.0 <= first - (t0 + timeout) < 3 * ls.period  # NaN one timeout after its last value
    assert all(dead for t, dead in seen if t >= first)
    assert not any(np.isnan(np.delete(st.tension, 2)))


def test_a_cell_mapped_otherwise_is_mapped_or_refused(rig):
    """A cell whose TPDO1 carries its status (0x6150) instead: 'configure' maps 0x9130 by SDO
    (the cell then reads the tension); 'static' refuses, naming the cell, writing nothing."""
    ls = rig
    cell = ls.net.load_cells[0]
    cell.od[(0x1A00, 1)] = 0x61500108
    cell.compile()
    ls.driver.configure()
    assert cell.od[(0x1A00, 1)] == 0x91300120
    _cycles(ls, 3)
    assert ls.driver.states.tension[0] == pytest.approx(ls.plant.tension[0], abs=0.5)
    cell.nmt = HB_PRE_OPERATIONAL
    cell.od[(0x1A00, 1)] = 0x61500108
    cell.compile()
    with pytest.raises(
        DriverInitializationError,
        match=r"load cell of cable index 0 \(node "
        r"21, bus 0\): TPDO1 does not carry 0x9130:01 at every SYNC",
    ):
        ls.driver.cells.configure(ls.driver.cells_sdo, False, 0.5)
    assert cell.od[(0x1A00, 1)] == 0x61500108


def test_the_kernel_decodes_each_type_where_it_is_mapped():
    """INTEGER16, INTEGER32 and REAL32 at bytes 0, 2 and 4 of their PDOs, against
    ``struct``; the scale and offset applied; the cable's tension and age."""
    raw = np.zeros((3, 8), dtype=np.uint8)
    raw[0, 0:2] = np.frombuffer(struct.pack("<h", -12345), np.uint8)
    raw[1, 2:6] = np.frombuffer(struct.pack("<i", -2_000_000_001), np.uint8)
    raw[2, 4:8] = np.frombuffer(struct.pack("<f", 123.25), np.uint8)
    tension, age = np.full(4, np.nan), np.full(4, np.inf)
    bits = np.zeros(1, np.uint32)
    cells_kernel(raw, np.array([0, 2, 4]), np.array([0, 1, 2]), np.array([0.01, 1e-6, 1.0]),
                 np.array([1.0, 0.0, -0.25]), np.ones(3, bool), np.full(3, -np.inf),
                 np.zeros(3), 1.0, np.full(3, 0.03), np.array([3, 0, 1]), bits,
                 bits.view(np.float32), tension, age)  # fmt: skip
    assert tension[3] == pytest.approx(-12345 * 0.01 + 1.0)
    assert tension[0] == pytest.approx(-2_000_000_001 * 1e-6)
    assert tension[1] == 123.0
    assert math.isnan(tension[2]) and age[2] == np.inf
