"""The simulated drives against an independent CANopen master: the ``canopen`` package, given
only the shipped EDS (``sim_backend/drives/cdprctl_winch_drive.eds``), on an in-process bus
while a thread steps the simulated robot in real time (1 ms steps). Issue 18's list of what a
master found wrong is checked item by item: mandatory objects, live objects readable by SDO,
sizes of expedited uploads, a client's abort not answered, segmented downloads, boot-up after
a reset and the communication objects restored, unsigned values, no SDO in STOPPED, modes
refused unless 0x6502 has them."""

from __future__ import annotations

import dataclasses
import time
import uuid

import can
import canopen
import pytest
from canopen.objectdictionary import ODVariable
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError
from conftest import CONFIG
from stepped_sim import SteppedSim, master_of

from cdprctl.model.drives import default_drives
from cdprctl.robot_file import load_robot
from drivers.cia402 import protocol as p
from drivers.cia402.objects import variables
from sim_backend.drives.dictionary import EDS

NODES = range(1, 9)


class Robot(SteppedSim):
    """rowc's eight drives on one bus, nodes 1-8, stepped by a thread in real time."""

    def __init__(self, channel: str):
        model = load_robot(CONFIG / "rowc.toml")
        drives = default_drives(model.name, model.n_cables, model.drives.rated_torque)
        model = dataclasses.replace(model, drives=drives)
        super().__init__(model, {"interface": "inprocess", "channel": channel})

    def drive(self, node: int):
        return self.net.nodes[0][node]


@pytest.fixture
def rig():
    channel = f"canopen-{uuid.uuid4().hex}"
    with master_of(Robot(channel), channel, EDS, NODES) as robot_network_nodes:
        yield robot_network_nodes


def test_the_scanner_finds_every_drive(rig):
    _robot, network, _ = rig
    network.scanner.search()
    deadline = time.monotonic() + 3.0
    while len(network.scanner.nodes) < len(NODES) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert sorted(network.scanner.nodes) == list(NODES)


def test_mandatory_objects_and_identity(rig):
    _, _, nodes = rig
    for n, node in nodes.items():
        assert node.sdo[0x1000].raw == 0x00020192  # CiA 402, servo drive
        assert node.sdo[0x1001].raw == 0
        identity = node.sdo[0x1018]
        assert identity[0].raw == 4
        assert identity[2].raw == 0x402 and identity[3].raw == 0x00010000
        assert identity[4].raw == 0x53494D00 + n  # a serial number per drive
        assert node.sdo[0x6502].raw & (1 << 7) and node.sdo[0x6502].raw & (1 << 9)


def test_every_object_uploads_with_its_own_size(rig):
    """Each object of the EDS is readable, and an expedited upload says its true size (it
    said 4 bytes for 1- and 2-byte objects); the device name (0x1008, 29 bytes) comes by a
    segmented upload."""
    _, _, nodes = rig
    node = nodes[3]
    for var in variables(node.object_dictionary):
        assert isinstance(var, ODVariable)
        data = node.sdo.upload(var.index, var.subindex)
        if var.data_type == 0x0009:  # VISIBLE_STRING
            assert data == b"cdprctl simulated winch drive"
        else:
            assert 8 * len(data) == len(var), (hex(var.index), var.subindex, data)


def test_live_objects_read_by_sdo_follow_the_drive(rig):
    robot, _, nodes = rig
    node, drive = nodes[2], robot.drive(2)
    assert node.sdo[0x6041].raw == p.STATUSWORD_OF[p.PowerState.SWITCH_ON_DISABLED]
    with robot.lock:
        counts = drive.axis.counts()
    assert node.sdo[0x6064].raw == pytest.approx(counts, abs=2)
    assert node.sdo[0x6077].raw == 0  # not enabled: no torque


def test_the_sto_state_is_0x3202_01_alone(rig):
    """maxon EPOS4's STO input states (0x3202:01, 3: both inputs energised) is a live object;
    the stored objects next to it answer their own values, a sub-index it lacks aborts."""
    import canopen

    _robot, _, nodes = rig
    node = nodes[1]
    assert node.sdo[0x3202][1].raw == 3
    assert node.sdo[0x3202][0].raw == 1  # its highest sub-index, stored: not the STO state
    assert node.sdo[0x60FE][1].raw == 0  # physical outputs: its default, not the STO state
    node.sdo[0x60FE][1].raw = 0x00010000
    assert node.sdo[0x60FE][1].raw == 0x00010000
    with pytest.raises(canopen.SdoAbortedError):
        node.sdo.upload(0x3202, 2)


def test_modes_only_from_0x6502(rig):
    _robot, _, nodes = rig
    node = nodes[1]
    node.sdo[0x6060].raw = 10
    assert node.sdo[0x6061].raw == 10
    with pytest.raises(SdoAbortedError) as err:
        node.sdo[0x6060].raw = 1  # profile position: not in 0x6502
    assert err.value.code == 0x06090030
    assert node.sdo[0x6061].raw == 10
    with pytest.raises(SdoAbortedError) as err:
        node.sdo[0x6061].raw = 8  # read-only
    assert err.value.code == 0x06010002
    with pytest.raises(SdoAbortedError) as err:
        node.sdo.upload(0x2000, 0)  # no such object
    assert err.value.code == 0x06020000


def test_values_are_typed_by_the_dictionary(rig):
    """0x1017 := 40,000 ms (UNSIGNED16) reads back 40,000 (stored signed it was −25,536 and
    the heartbeat stopped); a segmented download is a download, not its length (0x6076 went
    2,600 → 4)."""
    robot, _, nodes = rig
    node, drive = nodes[4], robot.drive(4)
    node.sdo[0x1017].raw = 40000
    assert node.sdo[0x1017].raw == 40000 and drive.od[(0x1017, 0)] == 40000
    node.sdo.download(0x6076, 0, (2600).to_bytes(4, "little"), force_segment=True)
    assert node.sdo[0x6076].raw == 2600 and drive.axis.rated_torque == pytest.approx(2.6)
    with pytest.raises(SdoAbortedError) as err:
        node.sdo.download(0x1017, 0, b"\x01\x02\x03\x04")  # 4 bytes into an UNSIGNED16
    assert err.value.code == 0x06070010


def test_a_clients_abort_is_not_answered(rig):
    _robot, network, _ = rig
    answers: list[bytes] = []
    network.subscribe(p.SDO_TX + 5, lambda cob, data, ts: answers.append(bytes(data)))
    network.send_message(p.SDO_RX + 5, bytes([0x80, 0x17, 0x10, 0, 0, 0, 0x04, 0x08]))
    time.sleep(0.2)
    assert answers == []


def test_reset_gives_a_boot_up_and_restores_the_communication_objects(rig):
    robot, _, nodes = rig
    node = nodes[6]
    node.sdo[0x1017].raw = 100
    node.sdo[0x6007].raw = 2
    node.nmt.send_command(p.NMT_RESET_COMMUNICATION)
    node.nmt.wait_for_bootup(timeout=2.0)
    assert node.sdo[0x1017].raw == 0  # communication object: back to its default
    assert node.sdo[0x6007].raw == 2  # application object: kept
    node.nmt.send_command(p.NMT_RESET_NODE)
    node.nmt.wait_for_bootup(timeout=2.0)
    assert node.sdo[0x6007].raw == 1  # everything back
    assert node.sdo[0x6072].raw == robot.drive(6).od[(p.OD_MAX_TORQUE, 0)]  # its own value


def test_no_sdo_in_nmt_stopped(rig):
    _, _, nodes = rig
    node = nodes[7]
    node.sdo.RESPONSE_TIMEOUT = 0.3
    node.nmt.send_command(p.NMT_STOP)
    time.sleep(0.05)
    with pytest.raises(SdoCommunicationError):
        _ = node.sdo[0x1000].raw
    node.nmt.send_command(p.NMT_PRE_OPERATIONAL)
    time.sleep(0.05)
    assert node.sdo[0x1000].raw == 0x00020192


def test_the_bus_speaks_only_standard_frames(rig):
    """Every frame the drives sent in these exchanges is a CiA 301 frame of a known kind."""
    _robot, network, nodes = rig
    seen: list[can.Message] = []
    listener = can.BufferedReader()
    network.notifier.add_listener(listener)
    nodes[8].nmt.send_command(p.NMT_RESET_NODE)
    _ = nodes[8].sdo[0x1018][4].raw
    time.sleep(0.1)
    while (msg := listener.get_message(0.0)) is not None:
        seen.append(msg)
    ids = {m.arbitration_id for m in seen}
    assert p.HEARTBEAT + 8 in ids and p.SDO_TX + 8 in ids
    assert all(m.arbitration_id & ~0x7F in (0x080, 0x180, 0x280, 0x580, 0x700) for m in seen)


def test_the_master_reads_and_changes_the_mapping(rig):
    """``tpdo.read()`` returns the mapping; a remap by ``PdoMap.save()`` (TPDO1: position
    actual alone) changes what the drive sends at the next SYNC."""
    robot, network, nodes = rig
    node = nodes[2]
    node.tpdo.read()
    node.rpdo.read()
    assert [v.index for v in node.tpdo[1]] == [0x6041, 0x6077, 0x6064]
    assert [v.index for v in node.rpdo[1]] == [0x6040, 0x6071]
    assert node.tpdo[1].cob_id == p.TPDO1 + 2 and node.tpdo[1].trans_type == 1
    assert not node.tpdo[2].enabled  # velocity: off until a master wants it
    node.tpdo[1].clear()
    node.tpdo[1].add_variable(0x6064)
    node.tpdo[1].trans_type = 1
    node.tpdo[1].enabled = True
    node.tpdo[1].save()
    node.nmt.state = "OPERATIONAL"
    got: list[bytes] = []
    network.subscribe(p.TPDO1 + 2, lambda cob, data, ts: got.append(bytes(data)))
    network.sync.transmit()
    deadline = time.monotonic() + 2.0
    while not got and time.monotonic() < deadline:
        time.sleep(0.01)
    with robot.lock:
        counts = robot.drive(2).axis.counts()
    assert len(got[0]) == 4  # position actual, nothing else
    assert int.from_bytes(got[0], "little", signed=True) == pytest.approx(counts, abs=2)


def torque_node_402(network, node_id: int):
    """canopen's CiA 402 master (``BaseNode402``) for one drive, given only the EDS: its state
    machine set up, cyclic synchronous torque, OPERATIONAL, the network's SYNC at 100 Hz."""
    network.nodes.pop(node_id, None)
    node = canopen.BaseNode402(node_id, str(EDS))
    network.add_node(node)
    node.sdo.RESPONSE_TIMEOUT = 1.0
    node.nmt.state = "PRE-OPERATIONAL"
    node.setup_402_state_machine()
    node.op_mode = "CYCLIC SYNCHRONOUS TORQUE"
    node.nmt.state = "OPERATIONAL"
    network.sync.start(0.01)
    return node


def test_base_node_402_enables_and_a_torque_by_rpdo_moves_the_winch(rig):
    """canopen's CiA 402 master (``BaseNode402``) against a simulated drive, given only the
    EDS: cyclic synchronous torque, OPERATION ENABLED through its state machine, then a
    target torque by RPDO and SYNC reaches the winch."""
    robot, network, _ = rig
    node = torque_node_402(network, 5)
    assert node.sdo[0x6061].raw == 10
    try:
        node.tpdo[1].wait_for_reception(timeout=2.0)
        with robot.lock:
            cable = robot.drive(5).cable
            hold = float(robot.plant.drum_ratio[cable] * robot.plant.tension[cable])
        rated = robot.drive(5).axis.rated_torque
        node.rpdo[1]["Target torque"].raw = round(hold / rated * 1000)
        node.rpdo[1].start(0.01)  # synchronous RPDO: sent every 10 ms, taken at each SYNC
        for state in ("READY TO SWITCH ON", "SWITCHED ON", "OPERATION ENABLED"):
            node.state = state
        assert node.state == "OPERATION ENABLED"
        with robot.lock:
            theta0 = float(robot.plant.theta[cable])
        node.rpdo[1]["Target torque"].raw = round(1.2 * hold / rated * 1000)
        node.rpdo[1].update()
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            with robot.lock:
                applied = float(robot.plant.motor_torque[cable])
            if applied > 1.1 * hold:
                break
            time.sleep(0.01)
        assert applied == pytest.approx(1.2 * hold, rel=0.01)
        time.sleep(0.3)
        with robot.lock:
            moved = float(robot.plant.theta[cable]) - theta0
        assert abs(moved) > 0.01  # rad: the winch turned under 20 % more than its holding torque
        assert robot.drive(5).axis.state is p.PowerState.OPERATION_ENABLED
    finally:
        node.rpdo[1].stop()
        network.sync.stop()


def test_an_open_safety_chain_faults_the_drive_until_released_and_reset(rig):
    """The e-stop as canopen's master sees it (``FaultEvent`` "estop", what `cdprctl sim
    --estop` schedules): an enabled drive goes to FAULT with maxon EPOS4's STO error 0x8A88
    (its EMCY, 0x603F), no torque, the brake closed, its STO inputs (EPOS4's 0x3202:01) read
    open; a fault reset is refused while the chain is open; once it closes the inputs read
    energised, the reset is taken and the drive enables again."""
    from sim_backend.faults import FaultEvent, FaultInjector

    robot, network, _ = rig
    node = torque_node_402(network, 5)
    try:
        node.tpdo[1].wait_for_reception(timeout=2.0)
        cable = robot.drive(5).cable
        with robot.lock:
            hold = float(robot.plant.drum_ratio[cable] * robot.plant.tension[cable])
        node.rpdo[1]["Target torque"].raw = round(hold / robot.drive(5).axis.rated_torque * 1000)
        node.rpdo[1].start(0.01)
        for state in ("READY TO SWITCH ON", "SWITCHED ON", "OPERATION ENABLED"):
            node.state = state
        with robot.lock:
            assert not robot.plant.brake[cable]
            estop = FaultEvent(robot.net.time + 0.05, "estop", duration=1.0)
            FaultInjector([estop]).attach(robot.net)
        assert node.sdo[0x3202][1].raw == 0x03  # EPOS4's "STO input states": energised
        node.emcy.wait(p.EMCY_STO, timeout=2.0)
        node.tpdo[1].wait_for_reception(timeout=1.0)
        assert node.state == "FAULT"
        assert node.sdo[0x603F].raw == p.EMCY_STO
        assert node.sdo[0x3202][1].raw == 0  # the inputs read open
        with robot.lock:
            assert robot.plant.brake[cable] and robot.plant.motor_torque[cable] == 0.0
        node.controlword = 0x00
        time.sleep(0.05)
        node.controlword = 0x80  # a fault reset's rising edge, the chain still open
        time.sleep(0.2)
        assert node.state == "FAULT" and node.sdo[0x603F].raw == p.EMCY_STO
        node.controlword = 0x00  # bit 7 down again: the master's reset below is an edge
        while robot.net.time < estop.time + estop.duration + 0.05:
            time.sleep(0.05)
        assert node.sdo[0x3202][1].raw == 0x03  # closed again, though still in fault
        node.state = "SWITCH ON DISABLED"  # canopen's master: the fault reset
        assert node.sdo[0x603F].raw == 0
        for state in ("READY TO SWITCH ON", "SWITCHED ON", "OPERATION ENABLED"):
            node.state = state
        assert robot.drive(5).axis.state is p.PowerState.OPERATION_ENABLED
    finally:
        node.rpdo[1].stop()
        network.sync.stop()
