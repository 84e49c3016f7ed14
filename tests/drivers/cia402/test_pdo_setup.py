"""The PDO set-up (``drivers/cia402/pdo_setup.py``) against a dictionary-backed drive: what a
refused write says, and the names its messages give the mapped objects (CiA 402-2's)."""

from __future__ import annotations

import pytest

from drivers.cia402 import pdo_setup as ps
from drivers.cia402 import protocol as p
from drivers.errors import DriverInitializationError, SdoAbortError

# CiA 402-2 (IEC 61800-7-201) object names, as the set-up's messages shorten them
CIA402_NAMES = {
    0x6040: "controlword", 0x6041: "statusword", 0x6060: "modes of operation",
    0x6061: "modes of operation display", 0x6062: "position demand", 0x6064: "position actual",
    0x606C: "velocity actual", 0x6071: "target torque", 0x6074: "torque demand",
    0x6077: "torque actual", 0x6078: "current actual", 0x607A: "target position",
    0x60B1: "velocity offset", 0x60B2: "torque offset", 0x60F4: "following error actual",
    0x60FD: "digital inputs", 0x60FF: "target velocity", 0x603F: "error code",
}  # fmt: skip


@pytest.mark.parametrize(("index", "name"), sorted(CIA402_NAMES.items()))
def test_a_mapping_names_each_cia402_object_as_the_standard_does(index, name):
    entry = (index << 16) | (0 << 8) | 32
    assert ps.describe((entry,)) == f"[0x{index:04X}:00 {name} (32 bit)]"


def test_a_mapping_names_vendor_and_unknown_objects_as_such():
    assert ps.describe((0x20300010,)) == "[0x2030:00 vendor's (16 bit)]"
    assert ps.describe((0x5FFF0108,)) == "[0x5FFF:01 vendor's (8 bit)]"  # the area's last
    assert ps.describe((0x60C20108,)) == "[0x60C2:01 CiA 402 object (8 bit)]"
    assert ps.describe(None) == "no count (sub-index 0 holds no value)"
    assert ps.describe(()) == "nothing"


class _Drive:
    """An object dictionary (index, sub) → value whose writes to ``refuse`` of another value
    than it holds abort with ``code`` (an object it cannot map there: what it had, it takes)."""

    def __init__(self, od: dict[tuple[int, int], int], refuse: tuple[int, int], code: int):
        self.od, self.refuse, self.code = dict(od), refuse, code

    def read(self, index: int, sub: int) -> int:
        return self.od[(index, sub)]

    def write(self, index: int, sub: int, value: int, size: int) -> None:
        if (index, sub) == self.refuse and value != self.od.get((index, sub)):
            raise SdoAbortError("refused", 1, index, sub, self.code)
        self.od[(index, sub)] = value


def _tpdo1_on_a_drive_that_refuses(code: int) -> str:
    pdo = ps.wanted(p.MODE_CSP, 1, False)[1]  # TPDO1
    od = {(pdo.comm, 1): pdo.cob_id, (pdo.comm, 2): 1, (pdo.mapping, 0): 1,
          (pdo.mapping, 1): 0x60410010}  # fmt: skip
    drive = _Drive(od, (pdo.mapping, 2), code)  # its second entry: not mappable there
    with pytest.raises(DriverInitializationError) as exc:
        ps.set_up(drive.read, drive.write, pdo, True, "node 1")
    return str(exc.value)


@pytest.mark.parametrize("code", [p.SDO_ABORT_READ_ONLY, 0x06040041, 0x06040042, 0x08000022,
                                  0x06010000, 0x06010001])  # fmt: skip
def test_a_refused_mapping_write_says_read_only_only_for_that_abort_code(code):
    """0x06010002 (CiA 301 Table 22: attempt to write a read-only object) is "read-only";
    every other code — larger (object cannot be mapped, PDO length exceeded, state) or
    smaller (unsupported access, write-only) — is given as its code."""
    text = _tpdo1_on_a_drive_that_refuses(code)
    pdo = ps.wanted(p.MODE_CSP, 1, False)[1]
    where = f"0x{pdo.mapping:04X}:02"
    if code == p.SDO_ABORT_READ_ONLY:
        assert f"({where} read-only)" in text, text
    else:
        assert f"({where} SDO abort 0x{code:08X})" in text and "read-only" not in text, text
    assert "put back as the drive had it" in text


def test_the_vendor_area_is_0x2000_to_0x5fff_both_included():
    """CiA 301 §7.4.1: 0x2000-0x5FFF manufacturer-specific; 0x1FFF is the communication area's
    last object and 0x6000 the device profile's first."""
    assert ps.describe((0x20000010,)) == "[0x2000:00 vendor's (16 bit)]"
    assert ps.describe((0x1FFF0010,)) == "[0x1FFF:00 CiA 402 object (16 bit)]"
    assert ps.describe((0x60000010,)) == "[0x6000:00 CiA 402 object (16 bit)]"


def test_a_mapped_entry_of_an_odd_bit_length_is_named_with_it():
    assert ps.describe((0x60FD0101,)) == "[0x60FD:01 digital inputs (1 bit)]"
    assert ps.describe((0x60FD0207,)) == "[0x60FD:02 digital inputs (7 bit)]"


def _od(pdo: ps.Pdo, cob: int, transmission: int = 1, entries=None) -> dict:
    entries = pdo.entries if entries is None else entries
    od = {(pdo.comm, 1): cob, (pdo.comm, 2): transmission, (pdo.mapping, 0): len(entries)}
    od.update({(pdo.mapping, k): e for k, e in enumerate(entries, 1)})
    return od


RPDO1_NODE2 = ps.wanted(p.MODE_CSP, 2, False)[0]  # COB-ID 0x202


@pytest.mark.parametrize("cob", [0x201, 0x203, 0x202 | p.PDO_NOT_VALID, 0x302])
def test_a_cob_id_other_than_the_nodes_is_a_difference_lower_or_higher(cob):
    diff = ps.differences(RPDO1_NODE2, cob, 1, RPDO1_NODE2.entries)
    assert diff == [f"0x1400:01 COB-ID expected 0x00000202, found 0x{cob:08X}"]


def test_the_cob_ids_bits_29_and_30_are_not_a_difference():
    assert ps.differences(RPDO1_NODE2, 0x40000202, 1, RPDO1_NODE2.entries) == []
    assert ps.differences(RPDO1_NODE2, 0x20000202, 1, RPDO1_NODE2.entries) == []


@pytest.mark.parametrize("transmission", [0, 2, 240, 254, 255])
def test_any_transmission_type_but_every_sync_is_a_difference(transmission):
    """CiA 301 Table 72: 0 acyclic synchronous, 2-240 every n-th SYNC, 254/255 event-driven:
    the codec needs the answer to every SYNC (1)."""
    diff = ps.differences(RPDO1_NODE2, 0x202, transmission, RPDO1_NODE2.entries)
    assert diff == [f"0x1400:02 transmission type expected 1 (every SYNC), found {transmission}"]


def test_a_pdo_wanted_disabled_is_as_wanted_only_with_its_not_valid_bit():
    off = ps.Pdo("RPDO1", p.RPDO1_COMM, p.RPDO1_MAP, 0x202, RPDO1_NODE2.entries, enabled=False)
    assert ps.differences(off, 0x202 | p.PDO_NOT_VALID, 1, off.entries) == []
    assert ps.differences(off, 0x202, 1, off.entries) == [
        "0x1400:01 COB-ID expected 0x80000202, found 0x00000202"]


def test_a_static_mapping_that_differs_refuses_the_start_naming_what_differs():
    od = _od(RPDO1_NODE2, 0x202, transmission=255)
    drive = _Drive(od, (0, 0), 0)
    with pytest.raises(DriverInitializationError) as exc:
        ps.set_up(drive.read, drive.write, RPDO1_NODE2, False, "node 2")
    assert str(exc.value) == (
        "node 2: RPDO1 is not what cdprctl's codec needs ([drives] pdo_mapping = \"static\": "
        "set it with the drive's tool, or use \"configure\"): "
        "0x1400:02 transmission type expected 1 (every SYNC), found 255")
    assert drive.od == od  # only read


def test_a_mapping_written_that_reads_back_otherwise_refuses_the_start():
    """A drive that takes every write and keeps none (as some do outside PRE-OPERATIONAL)."""
    od = _od(RPDO1_NODE2, 0x202, transmission=0)
    reads = dict(od)
    with pytest.raises(DriverInitializationError) as exc:
        ps.set_up(lambda i, s: reads[(i, s)], lambda *a: None, RPDO1_NODE2, True, "node 2")
    assert str(exc.value) == (
        "node 2: RPDO1 written but reads back differently: "
        "0x1400:02 transmission type expected 1 (every SYNC), found 0")


@pytest.mark.parametrize("bit30", [0, 0x40000000])
def test_configuring_another_nodes_pdo_writes_this_nodes_cob_id_keeping_bit_30(bit30):
    """The drive had node 1's COB-ID (0x201, odd); node 2's is written (0x202), bit 30 as the
    drive had it, the PDO disabled while its mapping changes (CiA 301 §7.5.2.35)."""
    od = _od(RPDO1_NODE2, 0x201 | bit30)
    drive = _Drive(od, (0, 0), 0)
    cobs: list[int] = []
    record = drive.write
    drive.write = lambda i, s, v, n: (cobs.append(v) if (i, s) == (0x1400, 1) else None,
                                      record(i, s, v, n))  # type: ignore[method-assign]
    assert ps.set_up(drive.read, drive.write, RPDO1_NODE2, True, "node 2") is True
    assert cobs == [0x202 | bit30 | p.PDO_NOT_VALID, 0x202 | bit30]
    assert drive.od == _od(RPDO1_NODE2, 0x202 | bit30)


@pytest.mark.parametrize("cob", [0x40000181 | p.PDO_NOT_VALID, 0x181 | p.PDO_NOT_VALID,
                                 0x40000181, 0x181])  # fmt: skip
def test_a_refused_write_puts_back_the_cob_id_as_it_was_enabled_or_not(cob):
    """A TPDO1 the drive had (bit 30 as it was, disabled or enabled) comes back bit for bit
    after its mapping's second entry is refused."""
    pdo = ps.wanted(p.MODE_CSP, 1, False)[1]
    od = _od(pdo, cob, entries=(0x60410010,))
    drive = _Drive(od, (pdo.mapping, 2), p.SDO_ABORT_READ_ONLY)
    with pytest.raises(DriverInitializationError, match="put back as the drive had it"):
        ps.set_up(drive.read, drive.write, pdo, True, "node 1")
    assert drive.od == od
