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
