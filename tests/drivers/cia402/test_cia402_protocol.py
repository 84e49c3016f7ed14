"""drivers/cia402/protocol.py against references it was not written from: the `canopen`
package's CiA 402 tables (statusword masks, controlwords, transitions), its NMT commands, SDO
command specifiers and EMCY classes, and the default COB-IDs of vendors' EDS files
(../shared/vendor_eds, read at test time). Every statusword and controlword is decoded, not a
sample: a mask off by one bit changes states nobody thought of."""

from __future__ import annotations

import re
import struct
import time

import canopen
import pytest
from canopen.emcy import EmcyError
from canopen.nmt import NMT_COMMANDS
from canopen.profiles.p402 import State402
from canopen.sdo import constants as sdo
from canopen.sdo.exceptions import SdoAbortedError
from conftest import canopen_network
from local_drives import VENDOR_EDS

from drivers.cia402 import protocol as p

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
    # CiA 402's eight states, each its own member: two equal values would make one an alias
    assert [s.name.replace("_", " ") for s in PS] == list(NAMES)
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


def test_each_command_is_the_controlword_the_canopen_package_sends_for_it():
    """The value each command is sent as (what the drive decodes, Table 28), against the
    canopen package's controlword constants; and each decodes back to its own command."""
    theirs = {p.Command.SHUTDOWN: State402.CW_SHUTDOWN, p.Command.SWITCH_ON: State402.CW_SWITCH_ON,
              p.Command.ENABLE_OPERATION: State402.CW_OPERATION_ENABLED,
              p.Command.DISABLE_VOLTAGE: State402.CW_DISABLE_VOLTAGE,
              p.Command.QUICK_STOP: State402.CW_QUICK_STOP,
              p.Command.FAULT_RESET: State402.CW_SWITCH_ON_DISABLED}  # fmt: skip
    assert set(theirs) == set(p.Command)
    for command, cw in theirs.items():
        assert int(command) == cw, command
        assert p.command_of(int(command)) is command


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


# the canopen package's EMCY class names → the words ours start with
EMCY_CLASS_WORDS = {
    "Generic Error": "generic", "Current": "current", "Voltage": "voltage",
    "Temperature": "temperature", "Device Hardware": "device hardware",
    "Device Software": "device software", "Additional Modules": "additional modules",
    "Monitoring": "monitoring", "External Error": "external",
    "Additional Functions": "additional functions", "Device Specific": "device specific",
}  # fmt: skip


def test_emcy_classes_are_the_canopen_packages():
    """CiA 301 Table 21's classes as the canopen package describes them, for every code the
    table's masks tell apart (each first digit, and xx00 / xxAB where it names only xx00)."""
    words = EMCY_CLASS_WORDS
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
    "OD_DEVICE_TYPE": "devicetype",
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

    network = canopen_network()
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


def test_ids_states_and_modes_are_the_canopen_packages():
    """The SYNC's COB-ID, the heartbeat's NMT states, a PDO's not-valid bit and the modes of
    operation, as the canopen package has them."""
    from canopen.nmt import NMT_STATES
    from canopen.pdo.base import PDO_NOT_VALID
    from canopen.profiles.p402 import OperationMode
    from canopen.sync import SyncProducer

    assert SyncProducer.cob_id == p.SYNC
    state = {name: code for code, name in NMT_STATES.items()}
    assert state["INITIALISING"] == p.HB_BOOTUP
    assert state["STOPPED"] == p.HB_STOPPED
    assert state["OPERATIONAL"] == p.HB_OPERATIONAL
    assert state["PRE-OPERATIONAL"] == p.HB_PRE_OPERATIONAL
    assert p.PDO_NOT_VALID == PDO_NOT_VALID
    assert OperationMode.NAME2CODE["CYCLIC SYNCHRONOUS POSITION"] == p.MODE_CSP
    assert OperationMode.NAME2CODE["CYCLIC SYNCHRONOUS TORQUE"] == p.MODE_CST


def test_pdo_mapping_entries_name_their_objects_and_sizes():
    """Each mapping entry (index << 16 | subindex << 8 | bits, CiA 301 §7.5.2.36) names the
    object it says (by the name the drive's EDS gives it) with that object's size."""
    from sim_backend.drives.dictionary import EDS

    od = canopen.import_od(str(EDS), 5)
    want = {0x60410010: ("statusword", 16), 0x60770010: ("torqueactualvalue", 16),
            0x60640020: ("positionactualvalue", 32), 0x606C0020: ("velocityactualvalue", 32),
            0x60400010: ("controlword", 16), 0x60710010: ("targettorque", 16),
            0x607A0020: ("targetposition", 32), 0x60B20010: ("torqueoffset", 16)}  # fmt: skip
    entries = list(p.TPDO1_MAPPING) + list(p.TPDO2_MAPPING)
    entries += [e for mapping in p.RPDO1_MAPPING.values() for e in mapping]
    for entry in entries:
        index, sub, bits = entry >> 16, entry >> 8 & 0xFF, entry & 0xFF
        obj = od[index] if sub == 0 else od[index][sub]
        name = re.sub(r"[^a-z0-9]", "", obj.name.lower())
        assert (name, bits) == want[entry], hex(entry)
        assert len(obj.encode_raw(0)) * 8 == bits, hex(entry)
    assert set(p.TPDO2_MAPPING) == {0x606C0020}


def test_every_sdo_download_size_has_its_command_specifier():
    """Expedited downloads of 1 to 4 bytes: CiA 301's command byte (n = 4 − size unused
    bytes), as the canopen package builds it."""
    for size in (1, 2, 3, 4):
        cmd = p.sdo_download(0x2000, 1, 0x123456, size)[0]
        assert cmd == sdo.REQUEST_DOWNLOAD | sdo.EXPEDITED | sdo.SIZE_SPECIFIED | (4 - size) << 2


def test_emcy_texts_and_classes_for_every_code_shape():
    """CiA 301 Table 21's named codes word for word, and each class for a code ending in 00,
    in 01 and in AB (the masks that tell xx00 from xxAB)."""
    named = {0x0000: "error reset or no error", 0x1000: "generic error",
             0x6100: "internal software", 0x9000: "external error"}  # fmt: skip
    for code, text in named.items():
        assert p.describe_emcy(code) == text, hex(code)
    words = EMCY_CLASS_WORDS
    for high in range(0x10, 0x100):
        for low in (0x00, 0x01, 0xAB):
            code = high << 8 | low
            if code in p.EMCY_CODES:
                continue
            theirs = EmcyError(code, 0, b"", 0.0).get_desc()
            ours = p.describe_emcy(code)
            expected = words[theirs] if theirs else "unknown class"
            assert ours.startswith(expected), (hex(code), theirs, ours)


def test_pdo_parameter_objects_and_cob_ids_are_the_canopen_packages():
    """Where the canopen package, as a master, looks for RPDO1, TPDO1 and TPDO2's
    communication and mapping parameters and what COB-IDs it predefines for them."""
    from sim_backend.drives.dictionary import EDS

    node = canopen.RemoteNode(5, canopen.import_od(str(EDS), 5))
    for maps, n, comm, mapping, cob in ((node.rpdo, 1, p.RPDO1_COMM, p.RPDO1_MAP, p.RPDO1),
                                        (node.tpdo, 1, p.TPDO1_COMM, p.TPDO1_MAP, p.TPDO1),
                                        (node.tpdo, 2, p.TPDO2_COMM, p.TPDO2_MAP, p.TPDO2)):
        m = maps.map[n]
        assert (m.com_record.od.index, m.map_array.od.index) == (comm, mapping)
        assert m.predefined_cob_id == cob + 5


def test_the_sdo_abort_codes_the_set_up_tells_apart_are_cia_301s():
    """Each code the set-up words (SDO_ABORT_TEXT) is one of CiA 301's, as the canopen
    package's table has them, and the named ones are the codes of their meaning there."""
    theirs = {text: code for code, text in SdoAbortedError.CODES.items()}
    meanings = [  # what the set-up meets and words (drive_setup.SKIPPABLE and the rest)
        "Object does not exist", "Subindex does not exist",
        "Attempt to write a read only object", "Data type and length code do not match",
        "Value range of parameter exceeded", "Value of parameter written too high",
        "Value of parameter written too low", "Resource not available",
        "Data cannot be transferred or stored to the application",
        "Data can not be transferred or stored to the application because of the present "
        "device state",
    ]  # fmt: skip
    assert set(p.SDO_ABORT_TEXT) == {theirs[m] for m in meanings}
    assert theirs["Object does not exist"] == p.SDO_ABORT_NO_OBJECT
    assert theirs["Subindex does not exist"] == p.SDO_ABORT_NO_SUB
    assert theirs["Attempt to write a read only object"] == p.SDO_ABORT_READ_ONLY


def test_the_safe_torque_off_codes_are_the_vendors_documented_ones():
    """STO as each vendor's drive reports it (docs/safety.md's table): maxon EPOS4 0x8A88
    "STO error", Technosoft iPOS 0x5441, Elmo Gold 0xFF20 — each named as safe torque off; a
    code one away from each is not (an ordinary drive fault)."""
    assert p.EMCY_STO == 0x8A88
    assert set(p.STO_CODES) == {0x8A88, 0x5441, 0xFF20}
    for code in (0x8A88, 0x5441, 0xFF20):
        assert "safe torque off" in p.describe_emcy(code) or "STO" in p.describe_emcy(code)
        for near in (code - 1, code + 1):
            assert near not in p.STO_CODES
