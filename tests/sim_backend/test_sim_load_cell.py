"""The simulated load cells (``sim_backend/drives/load_cell.py``) against an independent
CANopen master: the ``canopen`` package, given only the cell's EDS, on the in-process bus of
rowc_load_cells' first four cells while a thread steps the simulated robot in real time. The
device type, CiA 404's unit and decimal digits, the TPDO at each SYNC carrying the process
value of the plant's tension (INTEGER32 in 0.01 N), remapped by the master to REAL32 newtons
the standard way, and the cell's errors (offset, drift, a dead cell)."""

from __future__ import annotations

import struct
import time
import uuid

import canopen
import pytest
from conftest import CONFIG
from stepped_sim import SteppedSim, master_of

from cdprctl.robot_file import load_robot
from sim_backend.drives.load_cell import EDS
from sim_backend.plant import CdprPlant

CELLS = range(21, 25)  # the cells of cables 1-4, on rowc's first bus


class Robot(SteppedSim):
    """rowc_load_cells on two buses, at rest at home, stepped by a thread in real time."""

    def __init__(self, channels: list[str]):
        model = load_robot(CONFIG / "rowc_load_cells.toml")
        plant = CdprPlant(model)
        plant.set_pose(model.home.position, model.home.rotation, None)
        super().__init__(model, {"interface": "inprocess", "channels": channels}, plant)


@pytest.fixture
def rig():
    channels = [f"cells-{uuid.uuid4().hex}-{b}" for b in range(2)]
    with master_of(Robot(channels), channels[0], EDS, CELLS) as robot_network_nodes:
        yield robot_network_nodes


def _tpdo(network: canopen.Network, cob_id: int, syncs: int = 5) -> list[bytes]:
    """The data of the frames with ``cob_id`` answering ``syncs`` SYNCs sent by the master."""
    got: list[bytes] = []
    network.subscribe(cob_id, lambda _id, data, _t: got.append(bytes(data)))
    try:
        for _ in range(syncs):
            network.sync.transmit()
            time.sleep(0.01)
        deadline = time.monotonic() + 1.0
        while len(got) < syncs and time.monotonic() < deadline:
            time.sleep(0.01)
    finally:
        network.unsubscribe(cob_id)
    return got


def test_identity_and_cia404_objects(rig):
    _, _, nodes = rig
    for node in nodes.values():
        assert node.sdo[0x1000].raw & 0xFFFF == 404  # the profile: CiA 404, measuring devices
        assert node.sdo[0x6131][1].raw == 0x00210000  # CiA 303-2: newton, no prefix
        assert node.sdo[0x6132][1].raw == 2
        assert node.sdo[0x1A00][1].raw == 0x91300120  # TPDO1: 0x9130 sub 1, 32 bits


def test_the_tpdo_carries_the_cables_tension(rig):
    """In OPERATIONAL each SYNC gets a TPDO1 of 0x9130: the plant's tension in 0.01 N, within
    the simulated noise (0.1 N, 5 σ); not before the cell is started."""
    robot, network, nodes = rig
    assert _tpdo(network, 0x180 + 22, syncs=2) == []  # PRE-OPERATIONAL: no PDO
    nodes[22].nmt.state = "OPERATIONAL"
    frames = _tpdo(network, 0x180 + 22)
    assert len(frames) >= 4
    with robot.lock:
        tension = float(robot.plant.tension[1])
    assert tension > 10.0
    for data in frames:
        assert len(data) == 4
        assert struct.unpack("<i", data)[0] * 0.01 == pytest.approx(tension, abs=0.5)
    # the SDO upload answers the last sample, in the same units
    assert nodes[22].sdo[0x9130][1].raw * 0.01 == pytest.approx(tension, abs=0.5)


def test_master_remaps_to_real32_newtons(rig):
    """canopen's PDO API remaps TPDO1 to 0x6130 (REAL32, N) in PRE-OPERATIONAL; the cell
    then sends the tension as a float."""
    robot, network, nodes = rig
    node = nodes[23]
    node.tpdo.read()
    tp = node.tpdo[1]
    tp.clear()
    tp.add_variable(0x6130, 1)
    tp.trans_type = 1
    tp.enabled = True
    tp.save()
    assert node.sdo[0x1A00][1].raw == 0x61300120
    node.nmt.state = "OPERATIONAL"
    frames = _tpdo(network, 0x180 + 23)
    with robot.lock:
        tension = float(robot.plant.tension[2])
    assert frames and all(len(d) == 4 for d in frames)
    for data in frames:
        assert struct.unpack("<f", data)[0] == pytest.approx(tension, abs=0.5)
    # the mapping of a started cell is refused as CiA 301 says (0x08000022)
    with pytest.raises(canopen.SdoAbortedError) as exc:
        node.sdo[0x1A00][0].raw = 0
    assert exc.value.code == 0x08000022


def test_offset_drift_and_a_dead_cell(rig):
    robot, network, nodes = rig
    nodes[21].nmt.state = "OPERATIONAL"
    cell = robot.net.load_cells[0]
    with robot.lock:
        cell.noise = 0.0
        cell.offset = 3.0
        tension = float(robot.plant.tension[0])
    value = struct.unpack("<i", _tpdo(network, 0x195, syncs=2)[-1])[0] * 0.01
    assert value == pytest.approx(tension + 3.0, abs=0.02)
    with robot.lock:
        cell.drift_rate = 20.0  # N/s
        t0, d0 = robot.net.time, cell.drift
    time.sleep(0.2)
    with robot.lock:
        assert cell.drift - d0 == pytest.approx(20.0 * (robot.net.time - t0), abs=0.05)
        cell.silent = True
    assert _tpdo(network, 0x195, syncs=3) == []
