"""python-can's ``udp_multicast`` bus with a cyclic path that builds no ``can.Message``.

python-can's ``recv(0)`` costs a ``select``, a ``recvmsg``, a msgpack decode and a checked
``Message`` per frame, and ``udp_multicast`` loops every frame we send back to us: across
processes the driver's read phase spent most of its ~400 µs there (rowc, 250 Hz). This bus is
python-can's own (same socket, same wire format: any python-can peer talks to it) plus
``drain_frames``: every waiting datagram by non-blocking ``recv`` on the same socket until
none is left, decoded to ``(arbitration id, plain, data)`` — no select, no ``Message``. The set-up
(SDO, NMT, the ``canopen`` package) keeps python-can's path through ``recv``/``send``.
"""

from __future__ import annotations

import os
import socket
from collections.abc import Iterator
from typing import Any

import can
import msgpack
from can.interfaces.udp_multicast import UdpMulticastBus

MAX_DATAGRAM = 4096  # bytes: python-can's own receive buffer
MAX_STANDARD_ID = 0x7FF


class CyclicUdpMulticastBus(UdpMulticastBus):
    """``UdpMulticastBus`` (same arguments) with ``drain_frames`` for the control cycle."""

    def __init__(self, channel: str = UdpMulticastBus.DEFAULT_GROUP_IPv4, **kwargs: Any):
        super().__init__(channel, **kwargs)
        # A second handle on the same socket (its receive queue, its options): reading it by
        # MSG_DONTWAIT never changes the blocking mode python-can's send relies on.
        self._raw = socket.socket(fileno=os.dup(self.fileno()))
        self._unpack = msgpack.unpackb
        self._fd_frames = self.protocol is can.CanProtocol.CAN_FD
        #: datagrams that were no python-can frame (not msgpack, a field missing or of the wrong
        #: type): dropped like a frame with a bad CRC on a wire, never raised in the cycle
        self.malformed = 0

    def drain_frames(self) -> Iterator[tuple[int, bool, bytes]]:
        """Every frame waiting now, oldest first, as ``(arbitration id, plain, data)``; ``plain``
        is False for an extended-id, remote or error frame. Never blocks; ignores the software
        filters (the driver dispatches by id itself)."""
        recv, unpack = self._raw.recv, self._unpack
        while True:
            try:
                raw = recv(MAX_DATAGRAM, socket.MSG_DONTWAIT)
            except (BlockingIOError, InterruptedError):
                return
            try:
                d = unpack(raw)
                arb = d["arbitration_id"]
                data = d["data"]
                plain = not (d["is_extended_id"] or d["is_remote_frame"] or d["is_error_frame"])
                fd = d.get("is_fd", False)
                if type(arb) is not int or type(data) is not bytes or arb < 0:
                    raise ValueError(arb)
            except Exception:  # anything on the group that is not a frame: dropped, counted
                self.malformed += 1
                continue
            if fd and not self._fd_frames:
                continue  # python-can drops these too on a classic bus
            yield arb, plain and arb <= MAX_STANDARD_ID, data

    def shutdown(self) -> None:
        try:
            self._raw.close()
        finally:
            super().shutdown()
