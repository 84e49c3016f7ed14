"""CiA 402 drives of an independent stack for the driver to meet: a ``canopen.LocalNode`` (its
SDO server, NMT slave, heartbeat producer and PDO maps) over an object dictionary — cdprctl's
EDS with other defaults, or a vendor's EDS/DCF file from ../shared/vendor_eds — with the rules
a real drive's SDO server applies on top of what ``LocalNode`` checks itself (an absent object
0x06020000, an absent sub-index 0x06090011, a read-only one 0x06010002, a wrong size
0x06070010, no value 0x060A0023). Written here from CiA 301 and CiA 402, not from cdprctl's
simulated drives:

- the EDS's LowLimit/HighLimit: 0x06090031 (too high) / 0x06090032 (too low);
- a mode of operation 0x6502 does not list: 0x06090030;
- CiA 301 §7.5.2.35-38, the PDO mapping procedure: a valid PDO's COB-ID changes only through
  disabled (0x06090030); its mapping changes only while the PDO is disabled (0x06010000), the
  entries only while the count is 0 (0x06010000); an entry names an existing, mappable object
  of its own size (0x06040041); the count no more than the declared entries (0x06090031) nor
  more than 64 bits (0x06040042).

At each SYNC in OPERATIONAL a drive takes its RPDO1 (as mapped now), steps CiA 402's power
state machine, follows a position target at once (csp) and sends TPDO1 (as mapped now).
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

import canopen
import pytest
from canopen.sdo.exceptions import SdoAbortedError

from drivers.cia402 import protocol as p

# beside the checkout; CDPRCTL_VENDOR_EDS names them from elsewhere (make mutation's copies)
VENDOR_EDS = Path(
    os.environ.get("CDPRCTL_VENDOR_EDS")
    or Path(__file__).resolve().parents[2] / "shared" / "vendor_eds"
)
MODE_BIT = {p.MODE_CSP: 7, p.MODE_CST: 9}  # CiA 402 0x6502


def vendor_file(name: str) -> str:
    """A vendor's EDS/DCF by file name; the test skips, saying why, where they are absent."""
    path = VENDOR_EDS / name
    if not path.is_file():
        pytest.skip(f"{path} not found: the vendors' EDS files live in ../shared/vendor_eds "
                    "(CDPRCTL_VENDOR_EDS names another folder)")  # fmt: skip
    return str(path)


def _comm_of(index: int) -> int:
    """The communication parameter of a PDO object (0x14xx, 0x16xx, 0x18xx, 0x1Axx)."""
    return index - 0x200 if index & 0x200 else index


class LocalDrive:
    def __init__(self, network: canopen.Network, node_id: int, eds: str,
                 position: int = 1234, drift: int = 0, values: dict | None = None):  # fmt: skip
        """``position``: the first position actual (counts); ``drift``: counts it moves per
        SYNC by itself when no position target came (cst); ``values``: (index, sub) → value
        the drive holds before the master writes (what a vendor's tool set)."""
        self.node = canopen.LocalNode(node_id, canopen.import_od(eds, node_id))
        network.add_node(self.node)
        for (index, sub), value in (values or {}).items():
            var = self._var(index, sub)
            self.node.data_store.setdefault(index, {})[sub] = var.encode_raw(value)
        self.node.add_read_callback(self._read)
        # before the NMT slave's own callback: a refused write must not start a heartbeat
        self.node._write_callbacks.insert(0, self._check_write)
        self.writes: list[tuple[int, int, int]] = []  # what the drive took, in order
        self.refused: list[tuple[int, int, int]] = []  # (index, sub, abort code)
        self.state = p.PowerState.SWITCH_ON_DISABLED
        self.torque = 0  # per mille: cyclic synchronous torque's target
        self.target: int | None = None  # counts, position mode's target (None: none came)
        self.offset: int | None = None  # per mille, position mode's torque offset
        self.position = position
        self.drift = drift
        self.syncs = 0  # SYNCs served in OPERATIONAL
        self.sync_lengths: set[int] = set()  # the data lengths of the SYNCs it saw
        self.lock = threading.Lock()
        self.mapped = False
        network.subscribe(p.NMT, self._on_nmt)
        network.subscribe(p.SYNC, self._on_sync)

    # -- the object dictionary ---------------------------------------------------------------
    def _var(self, index: int, sub: int):
        obj = self.node.object_dictionary[index]
        return obj if isinstance(obj, canopen.objectdictionary.ODVariable) else obj[sub]

    def value(self, index: int, sub: int = 0) -> int | None:
        """The object's value as the drive holds it (None: absent or no value)."""
        try:
            return self._var(index, sub).decode_raw(self.node.get_data(index, sub))
        except (KeyError, SdoAbortedError):
            return None

    def _absent(self, index: int, sub: int) -> bool:
        """A sub-index the file does not declare (``canopen`` makes up array members on
        access; a drive aborts 0x06090011, CiA 301)."""
        obj = self.node.object_dictionary[index]
        return not isinstance(obj, canopen.objectdictionary.ODVariable) and (
            sub not in obj.subindices
        )

    def _read(self, index: int, subindex: int, od):
        if self._absent(index, subindex):
            raise SdoAbortedError(p.SDO_ABORT_NO_SUB)
        if index == p.OD_MODES_DISPLAY:  # the mode in effect: the one written
            return self.value(p.OD_MODES_OF_OPERATION)
        if index == p.OD_STATUSWORD:
            return p.STATUSWORD_OF[self.state]
        return None

    def _check_write(self, index: int, subindex: int, od, data: bytes) -> None:
        value = od.decode_raw(data)
        try:
            self._rules(index, subindex, od, value)
        except SdoAbortedError as exc:
            self.refused.append((index, subindex, exc.code))
            raise
        self.writes.append((index, subindex, value))

    def _rules(self, index: int, sub: int, od, value: int) -> None:
        if self._absent(index, sub):
            raise SdoAbortedError(p.SDO_ABORT_NO_SUB)
        if od.min is not None and value < od.min:
            raise SdoAbortedError(0x06090032)
        if od.max is not None and value > od.max:
            raise SdoAbortedError(0x06090031)
        if index == p.OD_MODES_OF_OPERATION:
            modes = self.value(p.OD_SUPPORTED_DRIVE_MODES)
            bit = MODE_BIT.get(value)
            if modes is not None and (bit is None or not modes >> bit & 1):
                raise SdoAbortedError(0x06090030)
        if 0x1400 <= index < 0x1C00:
            self._pdo_rules(index, sub, value)

    def _pdo_rules(self, index: int, sub: int, value: int) -> None:
        comm = _comm_of(index)
        cob = self.value(comm, 1)
        valid = cob is not None and not cob & p.PDO_NOT_VALID
        if index == comm:
            if sub == 1 and valid and not value & p.PDO_NOT_VALID and value & 0x7FF != cob & 0x7FF:
                raise SdoAbortedError(0x06090030)
            return
        if valid:
            raise SdoAbortedError(0x06010000)
        entries = self.node.object_dictionary[index]
        if sub == 0:
            bits = 0
            for k in range(1, value + 1):
                if k not in entries:
                    raise SdoAbortedError(0x06090031)
                bits += (self.value(index, k) or 0) & 0xFF
            if bits > 64:
                raise SdoAbortedError(0x06040042)
            return
        if self.value(index, 0) not in (0, None):
            raise SdoAbortedError(0x06010000)
        if value == 0:
            return
        try:
            target = self._var(value >> 16, (value >> 8) & 0xFF)
        except KeyError:
            raise SdoAbortedError(0x06040041) from None
        if not target.pdo_mappable or len(target) != value & 0xFF:
            raise SdoAbortedError(0x06040041)

    # -- the cycle ---------------------------------------------------------------------------
    def _on_nmt(self, can_id, data, timestamp) -> None:
        if data[0] == p.NMT_START and data[1] in (0, self.node.id):
            # the mapping as it is now, from its own dictionary (PDO 1 alone: a vendor's
            # file may leave the others' counts without a value)
            self.node.tpdo[1].read()
            self.node.rpdo[1].read()
            self.mapped = True

    def _on_sync(self, can_id, data, timestamp) -> None:
        self.sync_lengths.add(len(data))
        if not self.mapped or self.node.nmt.state != "OPERATIONAL":
            return
        with self.lock:
            self.syncs += 1
            rpdo = self.node.rpdo[1]
            if rpdo.is_received:
                rpdo.is_received = False
                values = {var.index: var.raw for var in rpdo}
                command = p.command_of(values.get(p.OD_CONTROLWORD, 0))
                nxt = p.TRANSITIONS.get((self.state, command))
                if nxt is not None:
                    self.state = nxt[0]
                self.torque = values.get(p.OD_TARGET_TORQUE, self.torque)
                self.target = values.get(p.OD_TARGET_POSITION, self.target)
                self.offset = values.get(p.OD_TORQUE_OFFSET, self.offset)
            enabled = self.state is p.PowerState.OPERATION_ENABLED
            if enabled and self.target is not None:
                self.position = self.target  # a perfect position loop
            elif self.target is None:
                self.position += self.drift
            live = {
                p.OD_STATUSWORD: p.STATUSWORD_OF[self.state],
                p.OD_POSITION_ACTUAL: (self.position + 2**31) % 2**32 - 2**31,  # INTEGER32
                p.OD_TORQUE_ACTUAL: self.torque if enabled else 0,
                p.OD_VELOCITY_ACTUAL: 0,
            }
            tpdo = self.node.tpdo[1]
            for var in tpdo:
                var.raw = live[var.index]
            tpdo.transmit()
