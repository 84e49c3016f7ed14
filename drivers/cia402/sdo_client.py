"""The set-up's SDO client (CiA 301 §7.2.4, expedited transfers) and NMT commands, on the
driver's own buses: a request sent, the answer taken from the frames the driver drains while
time passes by its ``wait`` (real or simulated). Outside the loop only."""

from __future__ import annotations

from typing import Any

import can

from drivers.cia402 import protocol as p
from drivers.errors import DriverInitializationError, DriverTimeoutError, SdoAbortError


class SdoClient:
    RETRY = 0.25  # s: a request (or its answer) lost on a lossy bus is sent again

    def __init__(self, driver: Any):
        """``driver``: a CAN winch driver with ``bus_of``/``node`` per cable, ``media``,
        ``_send``, ``_drain``, ``clock``, ``wait``, ``period`` and the ``_sdo_reply`` its
        decoding fills."""
        self.drv = driver

    def nmt_all(self, command: int) -> None:
        """An NMT command to every node of every bus (CiA 301 §7.2.8.3.1)."""
        for b in self.drv.media:
            self.drv._send(
                b, can.Message(arbitration_id=p.NMT, data=bytes([command, 0]), is_extended_id=False)
            )

    def exchange(self, c: int, request: bytes, timeout: float) -> bytes:
        """The answer of the drive of cable index ``c`` to ``request``; SdoAbortError when it
        aborts, DriverTimeoutError when it stays silent for ``timeout`` s."""
        drv = self.drv
        b, n = int(drv.bus_of[c]), int(drv.node[c])
        drv._sdo_reply.pop(c, None)
        msg = can.Message(arbitration_id=p.SDO_RX + n, data=request, is_extended_id=False)
        start = drv.clock()
        deadline = start + timeout
        next_try = start
        while c not in drv._sdo_reply:
            now = drv.clock()
            if now > deadline:
                raise DriverTimeoutError(
                    f"no SDO answer from node {n} (cable index {c}) within {timeout:g} s (is "
                    "the drive powered, on this bus, at this node id and bitrate? `cdprctl "
                    "drives scan --config F` lists the drives that answer)", c
                )
            if now >= next_try:
                drv._send(b, msg)  # expedited transfers are idempotent: safe to repeat
                next_try = now + self.RETRY
            drv.wait(drv.period / 4)
            drv._drain(drv.clock())
        reply = drv._sdo_reply.pop(c)
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
                f"node {int(self.drv.node[c])}: unexpected SDO answer {reply.hex()} reading "
                f"0x{index:04X}:{sub:02X}"
            )
        size = 4 - ((reply[0] >> 2) & 0x3) if reply[0] & 0x1 else 4
        return int.from_bytes(reply[4 : 4 + size], "little", signed=signed)

