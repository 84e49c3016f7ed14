"""The PDOs a CiA 402 drive must have for cdprctl's cyclic codec, checked and — with
``[drives] pdo_mapping = "configure"`` (the default) — written by SDO in PRE-OPERATIONAL, the
standard way (CiA 301 §7.5.2.35-38: PDO disabled by bit 31 of its COB-ID, mapping count 0,
entries, count, transmission type 1 (every SYNC), enabled), then read back. With ``"static"``
(a drive set up with its own tool) it is only read, and any difference refuses the start
naming node, object, what was expected and what was found; so does a drive whose mapping is
read-only and differs. Set-up only, never in the cycle.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from drivers.cia402 import protocol as p
from drivers.errors import DriverInitializationError, SdoAbortError

Read = Callable[[int, int], int]  # (index, sub) → value, unsigned
Write = Callable[[int, int, int, int], None]  # (index, sub, value, size in bytes)


@dataclass(frozen=True)
class Pdo:
    name: str
    comm: int  # communication parameter index
    mapping: int  # mapping parameter index
    cob_id: int  # 11-bit
    entries: tuple[int, ...]
    enabled: bool = True
    transmission: int = p.TRANSMISSION_EVERY_SYNC


# COB-ID bit 30 (a TPDO's "no RTR allowed"; reserved in an RPDO): kept as the drive has it — a
# drive may fix it (the EPOS4's TPDOs default to it set). Bit 29 (a 29-bit identifier) cleared:
# cdprctl's PDOs are 11-bit (CiA 301 §7.5.2.35).
KEPT_COB_BITS = 0x40000000


def wanted(mode: int, node_id: int, velocity_pdo: bool) -> list[Pdo]:
    """The PDOs cdprctl's codec expects of a drive at ``node_id`` in ``mode``."""
    pdos = [
        Pdo("RPDO1", p.RPDO1_COMM, p.RPDO1_MAP, p.RPDO1 + node_id, p.RPDO1_MAPPING[mode]),
        Pdo("TPDO1", p.TPDO1_COMM, p.TPDO1_MAP, p.TPDO1 + node_id, p.TPDO1_MAPPING),
    ]
    if velocity_pdo:
        pdos.append(Pdo("TPDO2", p.TPDO2_COMM, p.TPDO2_MAP, p.TPDO2 + node_id, p.TPDO2_MAPPING))
    return pdos


def found(read: Read, pdo: Pdo) -> tuple[int, int, tuple[int, ...] | None]:
    """(COB-ID with its valid bit, transmission type, mapping entries) as the drive has them;
    entries None when the drive holds no count (a vendor's EDS may give it no default)."""
    cob = read(pdo.comm, 1)
    transmission = read(pdo.comm, 2)
    try:
        count = read(pdo.mapping, 0)
    except SdoAbortError:
        return cob, transmission, None
    return cob, transmission, tuple(read(pdo.mapping, k) for k in range(1, count + 1))


def differences(pdo: Pdo, cob: int, transmission: int, entries: tuple[int, ...] | None
                ) -> list[str]:  # fmt: skip
    """What differs from ``pdo`` in what the drive has (``found``; empty: it is as wanted)."""
    out = []
    want_cob = pdo.cob_id | (0 if pdo.enabled else p.PDO_NOT_VALID)
    if cob & (p.PDO_NOT_VALID | 0x7FF) != want_cob:
        out.append(f"0x{pdo.comm:04X}:01 COB-ID expected 0x{want_cob:08X}, found 0x{cob:08X}")
    if transmission != p.TRANSMISSION_EVERY_SYNC:
        out.append(
            f"0x{pdo.comm:04X}:02 transmission type expected {p.TRANSMISSION_EVERY_SYNC} "
            f"(every SYNC), found {transmission}"
        )
    if entries != pdo.entries:
        out.append(
            f"0x{pdo.mapping:04X} mapping expected {describe(pdo.entries)}, found "
            f"{describe(entries)}"
        )
    return out


def write(write_sdo: Write, pdo: Pdo, kept_bits: int) -> None:
    """Writes ``pdo`` in CiA 301's order (raises ``SdoAbortError`` if the drive refuses);
    ``kept_bits``: the COB-ID's bits 29-30 (frame format, RTR) as the drive had them."""
    cob_id = pdo.cob_id | kept_bits
    write_sdo(pdo.comm, 1, cob_id | p.PDO_NOT_VALID, 4)
    write_sdo(pdo.mapping, 0, 0, 1)
    for k, entry in enumerate(pdo.entries, 1):
        write_sdo(pdo.mapping, k, entry, 4)
    write_sdo(pdo.mapping, 0, len(pdo.entries), 1)
    write_sdo(pdo.comm, 2, pdo.transmission, 1)
    if pdo.enabled:
        write_sdo(pdo.comm, 1, cob_id, 4)


def set_up(read: Read, write_sdo: Write, pdo: Pdo, configure: bool, who: str) -> bool:
    """``pdo`` on the drive ``who`` (for messages): checked, written if it differs and
    ``configure``, checked again. Returns True when it was written. Raises
    ``DriverInitializationError`` naming what differs; a write the drive refuses midway puts
    back what the drive had (and says so), or says the PDO is left disabled."""
    cob, transmission, entries = found(read, pdo)
    diff = differences(pdo, cob, transmission, entries)
    if not diff:
        return False
    if not configure:
        raise DriverInitializationError(
            f"{who}: {pdo.name} is not what cdprctl's codec needs ([drives] pdo_mapping = "
            f"\"static\": set it with the drive's tool, or use \"configure\"): " + "; ".join(diff)
        )
    kept = cob & KEPT_COB_BITS
    try:
        write(write_sdo, pdo, kept)
    except SdoAbortError as exc:
        why = "read-only" if exc.code == p.SDO_ABORT_READ_ONLY else f"SDO abort 0x{exc.code:08X}"
        raise DriverInitializationError(
            f"{who}: cannot set {pdo.name} (0x{exc.index:04X}:{exc.sub:02X} {why}) and it "
            f"differs: {'; '.join(diff)}; {restore(write_sdo, pdo, cob, transmission, entries)}"
        ) from exc
    diff = differences(pdo, *found(read, pdo))
    if diff:
        raise DriverInitializationError(
            f"{who}: {pdo.name} written but reads back differently: " + "; ".join(diff)
        )
    return True


def restore(write_sdo: Write, pdo: Pdo, cob: int, transmission: int,
            entries: tuple[int, ...] | None) -> str:  # fmt: skip
    """Puts back the PDO the drive had before a refused write; says what the drive is left
    with."""
    if entries is not None:
        before = Pdo(pdo.name, pdo.comm, pdo.mapping, cob & 0x7FF, entries,
                     enabled=not cob & p.PDO_NOT_VALID, transmission=transmission)  # fmt: skip
        try:
            write(write_sdo, before, cob & KEPT_COB_BITS)
            return f"{pdo.name} put back as the drive had it"
        except SdoAbortError:
            pass
    return (f"{pdo.name} left disabled (bit 31 of 0x{pdo.comm:04X}:01 set): the drive sends "
            "or takes no such PDO until it is set up again or reset")  # fmt: skip


def describe(entries: tuple[int, ...] | None) -> str:
    names = {
        0x6040: "controlword", 0x6041: "statusword", 0x6060: "modes of operation",
        0x6061: "modes of operation display", 0x6062: "position demand", 0x6064:
        "position actual", 0x606C: "velocity actual", 0x6071: "target torque", 0x6074:
        "torque demand", 0x6077: "torque actual", 0x6078: "current actual", 0x607A:
        "target position", 0x60B2: "torque offset", 0x60B1: "velocity offset", 0x60F4:
        "following error actual", 0x60FD: "digital inputs", 0x60FF: "target velocity",
        0x603F: "error code",
    }  # fmt: skip

    def name(index: int) -> str:
        if 0x2000 <= index < 0x6000:
            return "vendor's"
        return names.get(index, "CiA 402 object")

    if entries is None:
        return "no count (sub-index 0 holds no value)"
    if not entries:
        return "nothing"
    return "[" + ", ".join(
        f"0x{e >> 16:04X}:{(e >> 8) & 0xFF:02X} {name(e >> 16)} ({e & 0xFF} bit)"
        for e in entries
    ) + "]"
