"""A simulated drive's PDOs from its own communication and mapping objects (CiA 301 §7.4.7-8,
§7.5.2.35-38): what an RPDO carries and what a TPDO sends is what the mapping says, and a
master may change it in PRE-OPERATIONAL the standard way (PDO disabled by bit 31 of its
COB-ID, sub-index 0 set to 0, the entries, sub-index 0 set to their number, enabled again).

Each write is checked as a drive would (CiA 301's abort codes): not in OPERATIONAL
(0x08000022), an entry only while sub-index 0 is 0 and the PDO disabled (0x06010000), an
object that cannot be mapped in that direction or with another length (0x06040041), more than
64 bits (0x06040042), a new COB-ID for a valid PDO (0x06090030).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import can
from canopen import SdoAbortedError
from canopen.objectdictionary import ObjectDictionary

from drivers.cia402.objects import variable

# CiA 301 data types → struct formats (little endian)
_FORMAT = {0x0002: "b", 0x0003: "h", 0x0004: "i", 0x0005: "B", 0x0006: "H", 0x0007: "I",
           0x0008: "f"}  # fmt: skip

PDO_NOT_VALID = 0x80000000
RPDO_COMM = 0x1400  # its mapping parameter: + 0x200
TPDO_COMM = 0x1800
TPDO_COMMS = (TPDO_COMM, TPDO_COMM + 1)  # the drive's TPDOs: 1 (status), 2 (velocity)


@dataclass(frozen=True)
class Layout:
    """One PDO as its objects say: 11-bit COB-ID, valid, transmission type, the mapped
    objects (index, sub-index) in order, and the codec of its data."""

    cob_id: int
    valid: bool
    transmission: int
    entries: tuple[tuple[int, int], ...]
    codec: struct.Struct


def is_pdo_object(index: int) -> bool:
    return 0x1400 <= index <= 0x1BFF


def layout(od: ObjectDictionary, values: dict[tuple[int, int], int], comm: int) -> Layout:
    """The PDO whose communication parameter is ``comm`` (its mapping is ``comm + 0x200``)."""
    mapping = comm + 0x200
    cob = values[(comm, 1)]
    entries = []
    fmt = "<"
    for k in range(1, values[(mapping, 0)] + 1):
        index, sub, _ = split(values[(mapping, k)])
        entries.append((index, sub))
        fmt += _FORMAT[int(variable(od, index, sub).data_type or 0)]
    return Layout(
        cob & 0x7FF, not cob & PDO_NOT_VALID, values[(comm, 2)], tuple(entries), struct.Struct(fmt)
    )


def split(entry: int) -> tuple[int, int, int]:
    """A mapping entry: (index, sub-index, length in bits)."""
    return entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF


def check_write(
    od: ObjectDictionary,
    values: dict[tuple[int, int], int],
    operational: bool,
    index: int,
    sub: int,
    value: int,
) -> None:
    """Raises ``SdoAbortedError`` when the write of ``value`` to PDO object ``index``:``sub``
    is not one a drive takes now."""
    if operational:
        raise SdoAbortedError(0x08000022)  # not in the present device state
    receive = index < 0x1800
    comm = index if index & 0x0200 == 0 else index - 0x200
    if (comm, 1) not in values:
        raise SdoAbortedError(0x06020000)
    valid = not values[(comm, 1)] & PDO_NOT_VALID
    if index == comm:  # communication parameter
        if sub == 1 and valid and not value & PDO_NOT_VALID and value & 0x7FF != (
            values[(comm, 1)] & 0x7FF
        ):
            raise SdoAbortedError(0x06090030)  # a valid PDO's COB-ID changes only disabled
        return
    if valid:
        raise SdoAbortedError(0x06010000)  # the mapping of a valid PDO
    if sub == 0:
        total = 0
        for k in range(1, value + 1):
            if (index, k) not in values:
                raise SdoAbortedError(0x06090031)  # more entries than sub-indices
            total += split(values[(index, k)])[2]
        if total > 64:
            raise SdoAbortedError(0x06040042)
        return
    if values[(index, 0)] != 0:
        raise SdoAbortedError(0x06010000)  # entries only while sub-index 0 is 0
    if value == 0:
        return
    obj_index, obj_sub, bits = split(value)
    try:
        var = variable(od, obj_index, obj_sub)
    except KeyError:
        raise SdoAbortedError(0x06040041) from None
    readable, writable = "r" in var.access_type, "w" in var.access_type
    if (
        not var.pdo_mappable
        or var.data_type not in _FORMAT
        or len(var) != bits
        or (receive and not writable)
        or (not receive and not readable)
    ):
        raise SdoAbortedError(0x06040041)


class PdoEngine:
    """A node's PDO communication: RPDO1 and the TPDOs compiled from its objects (again after
    a write to them or a reset), an RPDO's values by the slots its owner keeps them in, and
    the TPDOs due at a SYNC (transmission type n: every n-th)."""

    def __init__(self, dictionary: Any, live: dict[int, Callable[[], int]],
                 slots: dict[int, int], owners: dict[int, Any], owner: Any):  # fmt: skip
        """``live``: the objects whose value is the node's state, by index (the rest are read
        from the dictionary); ``slots``: the place of each RPDO-mappable object in what
        ``decode_rpdo`` returns; ``owners``: COB-ID → node, shared by the nodes of a bus (who
        takes an RPDO), kept as ``owner``'s RPDO COB-ID changes."""
        self.dictionary, self.od, self.live = dictionary, dictionary.values, live
        self.slots, self.owners, self.owner = slots, owners, owner
        self.rx: Layout | None = None
        self.rx_slots: tuple[int, ...] = ()  # each RPDO entry's slot (-1: none)
        self.tx: list[Layout] = []
        self.tx_values: list[list[Callable[[], int]]] = []  # each TPDO entry's value, now
        self.tx_count = [0] * len(TPDO_COMMS)  # SYNCs since each TPDO was last sent
        self.length_errors = 0  # RPDOs shorter than their mapping: not processed
        self.compile()

    def compile(self) -> None:
        """The PDOs from the communication and mapping objects (after a write or a reset)."""
        old = self.rx
        self.rx = layout(self.dictionary.od, self.od, RPDO_COMM)
        self.rx_slots = tuple(self.slots.get(index, -1) for index, _ in self.rx.entries)
        self.tx = [layout(self.dictionary.od, self.od, comm) for comm in TPDO_COMMS]
        self.tx_values = [
            [self.live.get(index) or partial(self.od.__getitem__, (index, sub))
             for index, sub in tx.entries]
            for tx in self.tx
        ]  # fmt: skip
        if old is not None and self.owners.get(old.cob_id) is self.owner:
            del self.owners[old.cob_id]
        if self.rx.valid:
            self.owners[self.rx.cob_id] = self.owner

    def decode_rpdo(self, data: bytes) -> list[int | None] | None:
        """An RPDO's values by slot (None where not mapped); None when the RPDO is not valid
        or shorter than its mapping (CiA 301: a length error, not processed)."""
        rx = self.rx
        if rx is None or not rx.valid:
            return None
        if len(data) < rx.codec.size:
            self.length_errors += 1
            return None
        latched: list[int | None] = [None] * (max(self.slots.values()) + 1)
        for slot, value in zip(self.rx_slots, rx.codec.unpack_from(data), strict=True):
            if slot >= 0:
                latched[slot] = value
        return latched

    def tpdos(self) -> list[can.Message]:
        """The TPDOs due at this SYNC (transmission type n: every n-th SYNC), as mapped."""
        return due_tpdos(self.tx, self.tx_count,
                         lambda k, _: [value() for value in self.tx_values[k]])  # fmt: skip


def due_tpdos(tx: list[Layout], tx_count: list[int],
              values: Callable[[int, Layout], list[Any]]) -> list[can.Message]:  # fmt: skip
    """The TPDOs of ``tx`` due at this SYNC (transmission type n: every n-th SYNC; ``tx_count``
    the SYNCs since each was sent, counted here), each with ``values(k, tx[k])``."""
    out = []
    for k, pdo in enumerate(tx):
        if not pdo.valid or not 0 <= pdo.transmission <= 240:
            continue
        tx_count[k] += 1
        if tx_count[k] < max(1, pdo.transmission):
            continue
        tx_count[k] = 0
        out.append(can.Message(arbitration_id=pdo.cob_id, data=pdo.codec.pack(*values(k, pdo)),
                               is_extended_id=False))  # fmt: skip
    return out
