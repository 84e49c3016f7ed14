"""A simulated drive's object dictionary: the shipped EDS (``cdprctl_winch_drive.eds``), every
object the drive implements and nothing else, served by the ``canopen`` package's SDO server
(expedited and segmented transfers, sizes from the data types, CiA 301's abort codes, no
answer to a client's abort).

Values are typed by the dictionary. ``values`` holds the decoded value of every number with a
value (the EDS default, or what the drive stores, or what was written); the drive reads its
configuration from it and answers live objects (statusword, position, torque) through
``read``. ``write`` sees every SDO download before it is stored: it may refuse it with an
``SdoAbortedError``. A reset restores a range of objects to the drive's stored values.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache
from pathlib import Path
from typing import Any

import can
import canopen
from canopen.objectdictionary import ObjectDictionary, ODVariable

EDS = Path(__file__).with_name("cdprctl_winch_drive.eds")

Key = tuple[int, int]


@lru_cache(maxsize=128)
def _parsed(node_id: int) -> ObjectDictionary:
    """The EDS parsed for ``node_id`` ($NODEID resolved); definitions only, never mutated."""
    return canopen.import_od(str(EDS), node_id)


def variables(od: ObjectDictionary) -> list[ODVariable]:
    """Every variable of ``od``, sub-indices of records and arrays included."""
    out: list[ODVariable] = []
    for index in od:
        obj = od[index]
        if isinstance(obj, ODVariable):
            out.append(obj)
        else:
            out.extend(obj[sub] for sub in obj.subindices)
    return out


class Dictionary:
    def __init__(
        self,
        node_id: int,
        stored: dict[Key, int],
        read: Callable[[int, int], int | None],
        write: Callable[[int, int, int], None],
    ):
        """``stored``: the drive's own values over the EDS defaults (its non-volatile
        memory: what a reset restores); ``read(index, sub)``: a live value or None;
        ``write(index, sub, value)``: before a download is stored."""
        self.od = _parsed(node_id)
        self.node = canopen.LocalNode(node_id, self.od)
        # canopen's NMT slave would start its own heartbeat timer when 0x1017 is written: the
        # drive produces its heartbeat itself, on the simulator's clock
        self.node._write_callbacks.clear()
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        self.node.sdo.network = self  # type: ignore[assignment]  # answers: send_message
        self._read, self._write = read, write
        self._answer: can.Message | None = None
        self._stored = dict(stored)
        self.values: dict[Key, int] = {}
        self.reset(0x0000, 0x10000)

    def reset(self, first: int, end: int) -> None:
        """Objects ``first`` ≤ index < ``end`` back to the stored values (reset node: all;
        reset communication: 0x1000-0x1FFF)."""
        for index in [i for i in self.node.data_store if first <= i < end]:
            del self.node.data_store[index]
        for var in variables(self.od):
            if first <= var.index < end and isinstance(var.default, int):  # numbers
                key = (var.index, var.subindex)
                self.values[key] = int(self._stored.get(key, var.default))
        for key, value in self._stored.items():
            if first <= key[0] < end:
                self.node.data_store.setdefault(key[0], {})[key[1]] = self._variable(
                    *key
                ).encode_raw(value)

    def request(self, cob_id: int, data: bytes) -> can.Message | None:
        """The answer to one SDO request frame (None: a client's abort is not answered)."""
        self._answer = None
        self.node.sdo.on_request(cob_id, data, 0.0)
        return self._answer

    def send_message(self, can_id: int, data: Any, remote: bool = False) -> None:
        self._answer = can.Message(arbitration_id=can_id, data=bytes(data), is_extended_id=False)

    def _variable(self, index: int, sub: int) -> ODVariable:
        obj = self.od[index]
        return obj if isinstance(obj, ODVariable) else obj[sub]

    def _on_read(self, index: int, subindex: int, od: ODVariable) -> int | None:
        live = self._read(index, subindex)
        if live is not None:
            return live
        return self.values.get((index, subindex))

    def _on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        value = int(od.decode_raw(data))
        self._write(index, subindex, value)
        self.values[(index, subindex)] = value
