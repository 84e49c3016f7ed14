"""A simulated drive's object dictionary: the shipped EDS (``cdprctl_winch_drive.eds``), every
object the drive implements and nothing else, served by the ``canopen`` package's SDO server
(expedited and segmented transfers, sizes from the data types, CiA 301's abort codes, no
answer to a client's abort).

Values are typed by the dictionary. ``values`` holds the decoded value of every number (the
EDS default, or what the drive stores, or what was written); the drive reads its
configuration from it and answers live objects (statusword, position, torque) through
``read``. A download goes through ``check`` (it may refuse it with an ``SdoAbortedError``),
is stored, then ``written`` applies its effect. A reset restores a range of objects to the
drive's stored values.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import Any

import can
import canopen
from canopen.objectdictionary import ObjectDictionary, ODVariable

from drivers.cia402 import protocol as p
from drivers.cia402.objects import variables

EDS = Path(__file__).with_name("cdprctl_winch_drive.eds")
# NMT (CiA 301 §7.3.2): the state each command but a reset puts a node in
NMT_STATE_OF = {
    p.NMT_START: p.HB_OPERATIONAL,
    p.NMT_STOP: p.HB_STOPPED,
    p.NMT_PRE_OPERATIONAL: p.HB_PRE_OPERATIONAL,
}
NMT_RESETS = (p.NMT_RESET_NODE, p.NMT_RESET_COMMUNICATION)

Key = tuple[int, int]
Hook = Callable[[int, int, int], None]  # (index, sub, value)


@lru_cache(maxsize=128)
def _parsed(node_id: int, eds: Path = EDS) -> ObjectDictionary:
    """The EDS parsed for ``node_id`` ($NODEID resolved); definitions only, never mutated."""
    return canopen.import_od(str(eds), node_id)


class Dictionary:
    def __init__(
        self,
        node_id: int,
        stored: dict[Key, int],
        read: Callable[[int, int], int | float | None],
        check: Hook,
        written: Hook,
        eds: Path = EDS,
    ):
        """``eds``: the node's (default: the winch drive's); ``stored``: the drive's own values
        over the EDS defaults (its non-volatile memory: what a reset restores);
        ``read(index, sub)``: a live value or None; ``check`` before a download is stored,
        ``written`` after."""
        self.od = _parsed(node_id, eds)
        self.node = canopen.LocalNode(node_id, self.od)
        # canopen's NMT slave would start its own heartbeat timer when 0x1017 is written: the
        # drive produces its heartbeat itself, on the simulator's clock
        self.node._write_callbacks.clear()
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        self.node.sdo.network = self  # type: ignore[assignment]  # answers: send_message
        self._read, self._check, self._written = read, check, written
        self._answer: can.Message | None = None
        self._stored = dict(stored)
        self.values: dict[Key, int] = {}
        self.reset(0x0000, 0x10000)

    def reset(self, first: int, end: int) -> None:
        """Objects ``first`` ≤ index < ``end`` back to the stored values (reset node: all;
        reset communication: 0x1000-0x1FFF). Numbers are read from ``values`` (``value``);
        canopen's own store keeps nothing they need."""
        for index in [i for i in self.node.data_store if first <= i < end]:
            del self.node.data_store[index]
        for var in variables(self.od):
            if first <= var.index < end and isinstance(var.default, int):  # numbers
                key = (var.index, var.subindex)
                self.values[key] = int(self._stored.get(key, var.default))

    def reset_by(self, command: int) -> None:
        """The objects an NMT reset restores (CiA 301 §7.3.2.2): reset node all of them, reset
        communication 0x1000-0x1FFF."""
        if command == p.NMT_RESET_NODE:
            self.reset(0x0000, 0x10000)
        else:
            self.reset(0x1000, 0x2000)

    def value(self, index: int, sub: int) -> int | float | None:
        """An object's value now: live from the drive, else the stored number (None: not a
        number, e.g. the device name, which canopen answers from the EDS)."""
        live = self._read(index, sub)
        return live if live is not None else self.values.get((index, sub))

    def request(self, cob_id: int, data: bytes) -> can.Message | None:
        """The answer to one SDO request frame (None: a client's abort is not answered)."""
        self._answer = None
        self.node.sdo.on_request(cob_id, data, 0.0)
        return self._answer

    def send_message(self, can_id: int, data: Any, remote: bool = False) -> None:
        self._answer = can.Message(arbitration_id=can_id, data=bytes(data), is_extended_id=False)

    def _on_read(self, index: int, subindex: int, od: ODVariable) -> int | float | None:
        return self.value(index, subindex)

    def _on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        value = int(od.decode_raw(data))
        self._check(index, subindex, value)
        self.values[(index, subindex)] = value
        self._written(index, subindex, value)
