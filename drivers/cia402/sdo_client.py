"""The set-up's SDO client (CiA 301 §7.2.4, expedited transfers) and NMT commands, on the
driver's own buses: a request sent, the answer taken from the frames the driver drains while
time passes by its ``wait`` (real or simulated). Outside the loop only. It reaches the driver
through a port (:class:`SdoPort`), never the driver itself."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import can

from drivers.cia402 import protocol as p
from drivers.errors import DriverInitializationError, DriverTimeoutError, SdoAbortError


class SdoPort(Protocol):
    """What the SDO client needs of a driver: per cable its bus (``bus_of``) and node, the
    first bus of each medium (``media``: NMT goes there), ``send`` a frame on a bus, ``poll``
    the buses at a clock reading (the decoding puts each SDO answer into ``replies`` by
    cable), and the driver's time: ``clock``, ``wait``, ``period``."""

    bus_of: Any  # a sequence of ints (an array)
    node: Any
    media: Sequence[int]
    replies: dict[int, bytes]
    period: float

    def send(self, b: int, msg: can.Message) -> Any: ...
    def poll(self, t: float) -> None: ...
    def clock(self) -> float: ...
    def wait(self, dt: float) -> None: ...


@dataclass
class DriverSdoPort:
    """An :class:`SdoPort` made of a driver's parts (``Cia402Driver.sdo``)."""

    bus_of: Any
    node: Any
    media: Sequence[int]
    replies: dict[int, bytes]
    period: float
    send: Callable[[int, can.Message], Any]
    poll: Callable[[float], None]
    clock: Callable[[], float]
    wait: Callable[[float], None]


class SdoClient:
    RETRY = 0.25  # s: a request (or its answer) lost on a lossy bus is sent again

    def __init__(self, port: SdoPort):
        self.port = port

    def nmt_all(self, command: int) -> None:
        """An NMT command to every node of every bus (CiA 301 §7.2.8.3.1)."""
        for b in self.port.media:
            self.port.send(
                b, can.Message(arbitration_id=p.NMT, data=bytes([command, 0]), is_extended_id=False)
            )

    def exchange(self, c: int, request: bytes, timeout: float) -> bytes:
        """The answer of the drive of cable index ``c`` to ``request``; SdoAbortError when it
        aborts, DriverTimeoutError when it stays silent for ``timeout`` s."""
        port = self.port
        b, n = int(port.bus_of[c]), int(port.node[c])
        port.replies.pop(c, None)
        msg = can.Message(arbitration_id=p.SDO_RX + n, data=request, is_extended_id=False)
        start = port.clock()
        deadline = start + timeout
        next_try = start
        while c not in port.replies:
            now = port.clock()
            if now > deadline:
                raise DriverTimeoutError(
                    f"no SDO answer from node {n} (cable index {c}) within {timeout:g} s (is "
                    "the drive powered, on this bus, at this node id and bitrate? `cdprctl "
                    "drives scan --config F` lists the drives that answer)", c
                )
            if now >= next_try:
                port.send(b, msg)  # expedited transfers are idempotent: safe to repeat
                next_try = now + self.RETRY
            port.wait(port.period / 4)
            port.poll(port.clock())
        reply = port.replies.pop(c)
        if reply[0] == 0x80:
            code = int.from_bytes(reply[4:8], "little")
            index = int.from_bytes(request[1:3], "little")
            raise SdoAbortError(
                f"node {n} aborted SDO to 0x{index:04X}:{request[3]:02X}: code 0x{code:08X}",
                n, index, request[3], code,
            )  # fmt: skip
        return reply

    def write(self, c: int, index: int, sub: int, value: int, size: int, timeout: float) -> None:
        reply = self.exchange(c, p.sdo_download(index, sub, value, size), timeout)
        if reply[0] != 0x60:
            raise DriverInitializationError(f"unexpected SDO answer {reply.hex()}")

    def read(self, c: int, index: int, sub: int, timeout: float, signed: bool = True) -> int:
        reply = self.exchange(c, p.sdo_upload(index, sub), timeout)
        if reply[0] & 0xE0 != 0x40 or not reply[0] & 0x2:  # expedited uploads only
            raise DriverInitializationError(
                f"node {int(self.port.node[c])}: unexpected SDO answer {reply.hex()} reading "
                f"0x{index:04X}:{sub:02X}"
            )
        size = 4 - ((reply[0] >> 2) & 0x3) if reply[0] & 0x1 else 4
        return int.from_bytes(reply[4 : 4 + size], "little", signed=signed)

