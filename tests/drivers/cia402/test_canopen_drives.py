"""Our driver against drives of an independent stack: ``canopen`` ``LocalNode`` drives (its SDO
server, NMT slave and PDO maps) whose default mapping differs from the one cdprctl's codec
needs. The driver remaps them by SDO, reads the mapping back, enables them and runs cyclic
torque; a drive whose differing mapping is read-only refuses the start with a clear error.
Real time on an in-process bus (the drives answer from canopen's notifier thread)."""

from __future__ import annotations

import dataclasses
import math
import re
import time
import uuid

import numpy as np
import pytest
from conftest import CONFIG, canopen_network
from local_drives import LocalDrive

from cdprctl.model.drives import default_drives
from cdprctl.robot_file import load_robot
from drivers import DriverInitializationError, create_driver
from drivers.cia402 import protocol as p
from sim_backend.drives.dictionary import EDS

RATED_MNM = 5000  # seed000's drives: 5 N·m rated


def eds_variant(tmp_path, read_only: bool) -> str:
    """The shipped EDS with another default mapping (TPDO1: position actual then statusword;
    RPDO1: target torque then controlword) and the rated torque of seed000's drives;
    ``read_only``: the mapping entries cannot be written."""
    text = EDS.read_text()

    def section(name: str, body: str) -> None:
        nonlocal text
        text = re.sub(rf"\[{name}\]\n(.*?)\n\n", f"[{name}]\n{body}\n\n", text, flags=re.S)

    def entry(index: str, sub: int, value: int) -> None:
        access = "ro" if read_only else "rw"
        section(
            f"{index}sub{sub}",
            f"ParameterName=Application object {sub}\nObjectType=0x7\nDataType=0x0007\n"
            f"AccessType={access}\nDefaultValue=0x{value:08X}\nPDOMapping=0",
        )

    variants = (("1A00", (0x60640020, 0x60410010, 0)), ("1600", (0x60710010, 0x60400010)))
    for index, entries in variants:
        for k, value in enumerate(entries, 1):
            entry(index, k, value)
        count_access = "ro" if read_only else "rw"
        section(
            f"{index}sub0",
            "ParameterName=Number of mapped application objects in PDO\nObjectType=0x7\n"
            f"DataType=0x0005\nAccessType={count_access}\nDefaultValue=2\nPDOMapping=0",
        )
    text = text.replace(
        "ParameterName=Motor rated torque\nObjectType=0x7\nDataType=0x0007\nAccessType=rw\n"
        "DefaultValue=1000",
        "ParameterName=Motor rated torque\nObjectType=0x7\nDataType=0x0007\nAccessType=rw\n"
        f"DefaultValue={RATED_MNM}",
    )
    path = tmp_path / ("ro.eds" if read_only else "rw.eds")
    path.write_text(text)
    return str(path)


@pytest.fixture
def seed000_one_bus():
    model = load_robot(CONFIG / "seed000.toml")
    drives = dataclasses.replace(  # torque mode: the frames these drives' PDOs map
        default_drives(model.name, model.n_cables, model.drives.rated_torque), mode="cst"
    )
    assert drives.rated_torque * 1000 == RATED_MNM and drives.mode == "cst"
    return dataclasses.replace(model, drives=drives)


def bring_up(model, tmp_path, read_only: bool):
    channel = f"localnodes-{uuid.uuid4().hex}"
    network = canopen_network()
    network.connect(interface="inprocess", channel=channel)
    eds = eds_variant(tmp_path, read_only)
    drives = [LocalDrive(network, n, eds) for n in range(1, model.n_cables + 1)]
    overrides = {"interface": "inprocess", "channel": channel}
    driver = create_driver(model, period=model.control.period, bus_overrides=overrides)
    return network, drives, driver


def run_cycles(driver, model, targets=None) -> None:
    """30 control cycles in real time, every motor at 1.3 N·m (260 per mille of 5 N·m)."""
    torques = np.full(model.n_cables, 1.3)
    for _ in range(30):
        t = time.monotonic()
        driver.read(t)
        driver.write(t, torques, targets=targets)
        time.sleep(model.control.period)


def test_our_driver_remaps_local_node_drives_and_runs_them(seed000_one_bus, tmp_path):
    model = seed000_one_bus
    network, drives, driver = bring_up(model, tmp_path, read_only=False)
    try:
        driver.configure()
        assert driver.pdos_written == 2 * model.n_cables  # RPDO1 and TPDO1 of each
        node = drives[0].node
        assert [v.index for v in node.tpdo[1]] == [0x6041, 0x6077, 0x6064]
        assert [v.index for v in node.rpdo[1]] == [0x6040, 0x6071]
        assert driver.identities[2]["serial"] == 0x53494D03
        driver.activate()
        run_cycles(driver, model)
        assert all(d.state is p.PowerState.OPERATION_ENABLED for d in drives)
        assert all(d.torque == 260 for d in drives)
        driver.read(time.monotonic())
        np.testing.assert_allclose(driver.states.torque, 1.3, atol=0.01)
    finally:
        driver.shutdown()
        network.disconnect()


def test_gripper_drives_stay_in_torque_mode_among_drives_in_position_mode(tmp_path):
    """seed000_grippers in position mode: the grippers' drives (nodes 1 and 8) get cyclic
    synchronous torque (0x6060 = 10) and an RPDO1 of controlword and torque, the six others
    position mode (8), an RPDO1 of controlword, target and torque offset, and their following
    error; each
    frame as the ``canopen`` package decodes it by its own mapping."""
    model = load_robot(CONFIG / "seed000_grippers.toml")  # its two buses on one channel
    assert model.drives.mode == "csp"  # as shipped
    network, nodes, driver = bring_up(model, tmp_path, read_only=False)
    torque_nodes = (1, 8)
    try:
        driver.configure()
        for n, d in enumerate(nodes, 1):
            sdo = d.node.sdo
            mapped = [v.index for v in d.node.rpdo[1]]
            if n in torque_nodes:
                assert sdo[p.OD_MODES_OF_OPERATION].raw == p.MODE_CST
                assert mapped == [p.OD_CONTROLWORD, p.OD_TARGET_TORQUE]
            else:
                assert sdo[p.OD_MODES_OF_OPERATION].raw == p.MODE_CSP
                assert mapped == [p.OD_CONTROLWORD, p.OD_TARGET_POSITION, p.OD_TORQUE_OFFSET]
                assert sdo[p.OD_FOLLOWING_ERROR_WINDOW].raw > 0
        driver.activate()
        run_cycles(driver, model, targets=np.full(model.n_cables, 2.0 * math.pi))  # a turn
        assert all(d.state is p.PowerState.OPERATION_ENABLED for d in nodes)
        for n, d in enumerate(nodes, 1):
            if n in torque_nodes:
                assert (d.torque, d.target, d.offset) == (260, None, None)
            else:
                assert (d.torque, d.offset) == (0, 260)
                assert d.target == driver.encoder_cpr[n - 1]  # a turn, in counts
    finally:
        driver.shutdown()
        network.disconnect()


def test_a_read_only_mapping_that_differs_refuses_the_start(seed000_one_bus, tmp_path):
    model = seed000_one_bus
    network, _, driver = bring_up(model, tmp_path, read_only=True)
    try:
        with pytest.raises(DriverInitializationError) as err:
            driver.configure()
        text = str(err.value)
        assert "node 1" in text and "cannot set RPDO1" in text and "read-only" in text
        assert "0x1600 mapping expected [0x6040:00 controlword (16 bit), 0x6071:00" in text
        assert "found [0x6071:00 target torque (16 bit), 0x6040:00 controlword" in text
    finally:
        driver.shutdown()
        network.disconnect()
