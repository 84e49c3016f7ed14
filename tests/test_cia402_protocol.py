"""drivers/cia402/protocol.py against references it was not written from: the `canopen`
package's CiA 402 tables (statusword masks, controlwords, transitions), its NMT commands, SDO
command specifiers and EMCY classes, and the default COB-IDs of vendors' EDS files
(../shared/vendor_eds, read at test time). Every statusword and controlword is decoded, not a
sample: a mask off by one bit changes states nobody thought of."""

from __future__ import annotations

import os
import re
import struct
import time
from pathlib import Path

import canopen
import pytest
from canopen.emcy import EmcyError
from canopen.nmt import NMT_COMMANDS
from canopen.profiles.p402 import State402
from canopen.sdo import constants as sdo

from drivers.cia402 import protocol as p

# beside the checkout; CDPRCTL_VENDOR_EDS names them from elsewhere (make mutation's copies)
VENDOR_EDS = Path(
    os.environ.get("CDPRCTL_VENDOR_EDS")
    or Path(__file__).resolve().parents[2] / "shared" / "vendor_eds"
)
PS = p.PowerState
# canopen's state names → ours
NAMES = {
    "NOT READY TO SWITCH ON": PS.NOT_READY_TO_SWITCH_ON,
    "SWITCH ON DISABLED": PS.SWITCH_ON_DISABLED,
    "READY TO SWITCH ON": PS.READY_TO_SWITCH_ON,
    "SWITCHED ON": PS.SWITCHED_ON,
    "OPERATION ENABLED": PS.OPERATION_ENABLED,
    "QUICK STOP ACTIVE": PS.QUICK_STOP_ACTIVE,
    "FAULT REACTION ACTIVE": PS.FAULT_REACTION_ACTIVE,
    "FAULT": PS.FAULT,
}


def canopen_state(sw: int) -> p.PowerState | None:
    found = [NAMES[n] for n, (mask, value) in State402.SW_MASK.items() if sw & mask == value]
    assert len(found) <= 1
    return found[0] if found else None


def test_every_statusword_decodes_as_the_canopen_package_decodes_it():
    undefined = 0
    for sw in range(0x10000):
        theirs = canopen_state(sw)
        if theirs is None:  # no state of CiA 402 Table 30: read as not ready (never enabled)
            undefined += 1
            assert p.decode_statusword(sw) is PS.NOT_READY_TO_SWITCH_ON, hex(sw)
        else:
            assert p.decode_statusword(sw) is theirs, hex(sw)
    assert undefined > 0  # and those were checked too


def test_the_statusword_each_state_reports_decodes_to_that_state():
    for state, sw in p.STATUSWORD_OF.items():
        assert p.decode_statusword(sw) is state
        assert canopen_state(sw) is state


def table28(cw: int) -> p.Command | None:
    """CiA 402 Table 28, bits 7, 3, 2, 1, 0 (x: any), written out here."""
    if cw & 0x80:
        return p.Command.FAULT_RESET  # 0 → 1 of bit 7
    if cw & 0x02 == 0:  # 0 x x 0 x
        return p.Command.DISABLE_VOLTAGE
    if cw & 0x06 == 0x02:  # 0 x 0 1 x
        return p.Command.QUICK_STOP
    if cw & 0x07 == 0x06:  # 0 x 1 1 0
        return p.Command.SHUTDOWN
    if cw & 0x0F == 0x07:  # 0 0 1 1 1: switch on, or disable operation
        return p.Command.SWITCH_ON
    if cw & 0x0F == 0x0F:  # 0 1 1 1 1
        return p.Command.ENABLE_OPERATION
    return None


def test_every_controlword_encodes_the_command_of_table_28():
    for cw in range(0x10000):
        assert p.command_of(cw) is table28(cw & 0xFF), hex(cw)
    # what the driver sends is what the canopen package sends for the same state change
    for code, name in State402.CW_CODE_COMMANDS.items():
        if name in NAMES and name != "SWITCH ON DISABLED":
            assert p.command_of(code) is not None


def test_transitions_agree_with_the_canopen_packages_table():
    """Each of our transitions is one the canopen package drives with a controlword that
    decodes to our command; the numbers are CiA 402 Figure 14's."""
    # Figure 14: number, from, to (the states' initials)
    figure_14 = ("2 SOD RTSO, 3 RTSO SO, 4 SO OE, 5 OE SO, 6 SO RTSO, 7 RTSO SOD, 8 OE RTSO, "
                 "9 OE SOD, 10 SO SOD, 11 OE QSA, 12 QSA SOD, 15 F SOD, 16 QSA OE")  # fmt: skip
    initials = {"SOD": PS.SWITCH_ON_DISABLED, "RTSO": PS.READY_TO_SWITCH_ON,
                "SO": PS.SWITCHED_ON, "OE": PS.OPERATION_ENABLED, "QSA": PS.QUICK_STOP_ACTIVE,
                "F": PS.FAULT}  # fmt: skip
    numbers = {}
    for entry in figure_14.split(", "):
        n, a, b = entry.split()
        numbers[(initials[a], initials[b])] = int(n)
    ours = NAMES_BY_STATE
    for (state, command), (nxt, number) in p.TRANSITIONS.items():
        assert numbers[(state, nxt)] == number, (state, command, nxt)
        theirs = State402.TRANSITIONTABLE.get((ours[state], ours[nxt]))
        if theirs is not None:  # the canopen package's controlword takes our drives there too
            assert p.TRANSITIONS[(state, p.command_of(theirs))][0] is nxt, (state, hex(theirs))
    assert set(numbers) == {(s, n) for (s, _), (n, _) in p.TRANSITIONS.items()}


NAMES_BY_STATE = {v: k for k, v in NAMES.items()}


def test_nmt_commands_and_sdo_specifiers_are_the_canopen_packages():
    assert NMT_COMMANDS["OPERATIONAL"] == p.NMT_START
    assert NMT_COMMANDS["STOPPED"] == p.NMT_STOP
    assert NMT_COMMANDS["PRE-OPERATIONAL"] == p.NMT_PRE_OPERATIONAL
    assert NMT_COMMANDS["RESET"] == p.NMT_RESET_NODE
    assert NMT_COMMANDS["RESET COMMUNICATION"] == p.NMT_RESET_COMMUNICATION
    for size, value, packed in ((1, 0x7F, b"\x7f"), (2, -5, struct.pack("<h", -5)),
                                (4, -123456, struct.pack("<i", -123456)),
                                (4, 0xFFFFFFFF, b"\xff" * 4)):  # fmt: skip
        cmd, index, sub, data = struct.unpack("<BHB4s", p.sdo_download(0x60B2, 3, value, size))
        assert cmd == sdo.REQUEST_DOWNLOAD | sdo.EXPEDITED | sdo.SIZE_SPECIFIED | (4 - size) << 2
        assert (index, sub) == (0x60B2, 3) and data == packed.ljust(4, b"\0")
    assert p.sdo_upload(0x1018, 2) == struct.pack("<BHB4s", sdo.REQUEST_UPLOAD, 0x1018, 2, b"")


def test_emcy_classes_are_the_canopen_packages():
    """CiA 301 Table 21's classes as the canopen package describes them, for every code the
    table's masks tell apart (each first digit, and xx00 / xxAB where it names only xx00)."""
    words = {"Generic Error": "generic", "Current": "current", "Voltage": "voltage",
             "Temperature": "temperature", "Device Hardware": "device hardware",
             "Device Software": "device software", "Additional Modules": "additional modules",
             "Monitoring": "monitoring", "External Error": "external",
             "Additional Functions": "additional functions",
             "Device Specific": "device specific"}  # fmt: skip
    checked = 0
    for code in range(0x1000, 0x10000, 0x0101):  # every first and second digit
        theirs = EmcyError(code, 0, b"", 0.0).get_desc()
        if code in p.EMCY_CODES:
            continue
        ours = p.describe_emcy(code)
        if theirs == "":
            assert ours.startswith("unknown class"), hex(code)
        else:
            assert ours.startswith(words[theirs]), (hex(code), theirs, ours)
            assert ours.endswith(f"error (code 0x{code:04X})")
        checked += 1
    assert checked > 200
    # the codes cdprctl names: each in its class
    for code, text in p.EMCY_CODES.items():
        assert p.describe_emcy(code) == text
        desc = EmcyError(code, 0, b"", 0.0).get_desc()
        if code and desc:  # (CiA 402's 0x5xxx beyond CiA 301's 0x50xx: no class there)
            theirs = words[desc]
            assert any(code & mask == value and name.startswith(theirs)
                       for value, mask, name in p.EMCY_CLASSES), (hex(code), text)  # fmt: skip
    assert p.EMCY_CODES[p.EMCY_FOLLOWING_ERROR] == "following error"  # CiA 402: 0x8611


@pytest.mark.skipif(not VENDOR_EDS.is_dir(), reason="../shared/vendor_eds not present")
@pytest.mark.parametrize("eds", sorted(VENDOR_EDS.glob("*.[ed][dc][sf]")) if VENDOR_EDS.is_dir()
                         else [], ids=lambda f: f.name)  # fmt: skip
def test_cob_ids_and_objects_are_those_of_vendors_files(eds):
    """The pre-defined connection set (CiA 301) as drive vendors' files default it, for a
    node 5; the objects cdprctl names, as the files name them."""
    od = canopen.import_od(str(eds), 5)
    assert od[p.RPDO1_COMM][1].default & 0x7FF == p.RPDO1 + 5
    assert od[p.TPDO1_COMM][1].default & 0x7FF == p.TPDO1 + 5
    assert od[p.TPDO2_COMM][1].default & 0x7FF == p.TPDO2 + 5


# CiA 301/402's names of the objects cdprctl reads and writes (spaces, case and "_" aside)
OBJECT_NAMES = {
    "OD_ERROR_REGISTER": "errorregister", "OD_ERROR_CODE": "errorcode",
    "OD_MAX_TORQUE": "maxtorque", "OD_SUPPORTED_DRIVE_MODES": "supporteddrivemodes",
    "OD_CONTROLWORD": "controlword", "OD_STATUSWORD": "statusword",
    "OD_MODES_OF_OPERATION": "modesofoperation", "OD_MODES_DISPLAY": "modesofoperationdisplay",
    "OD_POSITION_ACTUAL": "positionactualvalue", "OD_VELOCITY_ACTUAL": "velocityactualvalue",
    "OD_TARGET_TORQUE": "targettorque", "OD_RATED_TORQUE": "motorratedtorque",
    "OD_TORQUE_ACTUAL": "torqueactualvalue", "OD_ABORT_CONNECTION": "abortconnectionoptioncode",
    "OD_PRODUCER_HEARTBEAT": "producerheartbeattime",
    "OD_SYNC_COUNTER_OVERFLOW": "synchronouscounteroverflowvalue",
    "OD_TARGET_POSITION": "targetposition", "OD_TORQUE_OFFSET": "torqueoffset",
    "OD_IDENTITY": "identityobject", "OD_FOLLOWING_ERROR_WINDOW": "followingerrorwindow",
    "OD_FOLLOWING_ERROR_TIMEOUT": "followingerrortimeout",
}  # fmt: skip


@pytest.mark.skipif(not VENDOR_EDS.is_dir(), reason="../shared/vendor_eds not present")
def test_object_indices_are_where_vendors_files_put_those_objects():
    """Each object index cdprctl uses holds, in every vendor's file that has it, the object of
    that name; and each is in at least one of the files."""
    assert set(OBJECT_NAMES) == {k for k in vars(p) if k.startswith("OD_")}
    found = dict.fromkeys(OBJECT_NAMES, 0)
    for eds in sorted(VENDOR_EDS.glob("*.[ed][dc][sf]")):
        od = canopen.import_od(str(eds), 5)
        for const, name in OBJECT_NAMES.items():
            index = getattr(p, const)
            if index in od:
                assert re.sub(r"[^a-z0-9]", "", od[index].name.lower()) == name, (eds.name, const)
                found[const] += 1
    assert all(found.values()), found


def test_emcy_codes_are_cia_402s():
    """The texts cdprctl prints for the codes of CiA 301 Table 21 / CiA 402 Table 2."""
    spec = {0x2310: "over-current", 0x2320: "short circuit", 0x3210: "over-voltage",
            0x3220: "under-voltage", 0x4210: "temperature, device", 0x4310: "temperature, drive",
            0x5530: "data storage", 0x6100: "software", 0x7121: "motor blocked",
            0x7300: "sensor", 0x7305: "incremental sensor 1", 0x8110: "CAN overrun",
            0x8120: "error passive", 0x8130: "heartbeat", 0x8140: "bus off",
            0x8611: "following error", 0x8612: "reference limit", 0x9000: "external",
            0xFF00: "device specific"}  # fmt: skip
    for code, words in spec.items():
        assert words in p.describe_emcy(code), hex(code)


def test_heartbeat_and_emcy_ids_are_what_a_canopen_master_listens_on():
    """Frames sent with our COB-IDs, from another bus, reach a canopen master's node 7 as its
    heartbeat and its EMCY."""
    import can

    network = canopen.Network()
    network.connect(interface="virtual", channel="cia402-protocol-ids")
    drive = can.Bus(interface="virtual", channel="cia402-protocol-ids")
    try:
        node = network.add_node(canopen.RemoteNode(7, canopen.ObjectDictionary()))
        drive.send(frame(p.HEARTBEAT + 7, bytes([p.HB_PRE_OPERATIONAL])))
        drive.send(frame(p.EMCY + 7, p.EMCY_STRUCT.pack(0x8611, 0x80, b"")))
        deadline = time.monotonic() + 2.0
        while (node.nmt.state != "PRE-OPERATIONAL" or not node.emcy.log) and (
            time.monotonic() < deadline
        ):
            time.sleep(0.01)
        assert node.nmt.state == "PRE-OPERATIONAL"
        assert [e.code for e in node.emcy.log] == [0x8611]
    finally:
        drive.shutdown()
        network.disconnect()


def frame(arb: int, data: bytes):
    import can

    return can.Message(arbitration_id=arb, data=data, is_extended_id=False)
