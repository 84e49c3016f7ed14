"""A CAN medium between two processes of one machine: a connected pair of Unix datagram
sockets, for ``run --sim``'s simulated robot in a process of its own.

Why not udp_multicast: the simulated robot stands for drives with processors of their own, so
it runs beside the daemon, not in its loop's thread; across udp_multicast a 1 kHz cycle of
rowc spent ~130 µs of its compute reading and writing (msgpack, the multicast loop-back of
every frame sent, one datagram per frame). Here a cycle's frames go in one datagram as
SocketCAN lays them out (``struct can_frame``: 32-bit id with the EFF/RTR/ERR flags, length,
8 data bytes) behind the sender's monotonic clock (both processes share it); nothing is
looped back, nobody else is on the medium.

python-can's interface (``recv``/``send``, for the set-up, SDO and the ``canopen`` package)
plus the control cycle's path that ``drivers/transport.py`` looks for: ``drain_frames`` to read,
``stage``/``flush`` to send. The channel is the socket's file descriptor (the bus owns it).
Classic CAN frames only.
"""

from __future__ import annotations

import collections
import select
import socket
import struct
import time
from collections.abc import Iterator
from typing import Any

import can

from drivers.cyclic_path import StagedFrames

HEADER = struct.Struct("<dI")  # the sender's monotonic clock at sending (s), frames in it
FRAME = struct.Struct("<IB3x8s")  # SocketCAN's struct can_frame
MAX_FRAMES = 64  # a datagram's frames (a cycle of rowc: 9-17)
DATAGRAM = HEADER.size + MAX_FRAMES * FRAME.size
EFF, RTR, ERR = 0x80000000, 0x40000000, 0x20000000  # <linux/can.h> CAN_*_FLAG
MAX_STANDARD_ID = 0x7FF
SOCKET_BUFFER = 1 << 20  # bytes each way: a stalled peer's ~1 s of cycles, not a lost frame


def socket_pair() -> tuple[socket.socket, socket.socket]:
    """Two connected ends of a medium (one per process: pass one's ``fileno()`` on)."""
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_DGRAM)
    for s in (a, b):
        s.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCKET_BUFFER)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER)
    return a, b


def can_id_of(msg: can.Message) -> int:
    """SocketCAN's ``can_id`` word of ``msg``."""
    arb = msg.arbitration_id
    return (
        (arb | EFF if msg.is_extended_id else arb)
        | (RTR if msg.is_remote_frame else 0)
        | (ERR if msg.is_error_frame else 0)
    )


class PairBus(StagedFrames, can.BusABC):
    """One end of a ``socket_pair``; ``channel``: its file descriptor (owned from now)."""

    def __init__(self, channel: Any, **kwargs: Any):
        super().__init__(channel=channel, **kwargs)
        self.channel_info = f"socket pair fd {channel}"
        self._channel = str(channel)
        self._sock = socket.socket(fileno=int(channel))
        self._sock.setblocking(False)
        self._out = bytearray(DATAGRAM)
        self._in = bytearray(DATAGRAM)
        self._in_view = memoryview(self._in)
        self._staged = 0
        self._pending: collections.deque[can.Message] = collections.deque()
        #: datagrams that were no batch of frames (a length off the layout): dropped, counted
        self.malformed = 0

    def fileno(self) -> int:
        return self._sock.fileno()

    # -- python-can's path -----------------------------------------------------------------
    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.is_fd:
            raise can.CanOperationError("the socket pair medium carries classic CAN frames only")
        out = self._out
        HEADER.pack_into(out, 0, time.monotonic(), 1)
        FRAME.pack_into(out, HEADER.size, can_id_of(msg), msg.dlc, bytes(msg.data))
        try:
            self._sock.send(memoryview(out)[: HEADER.size + FRAME.size])
        except OSError as exc:  # the peer's buffer full, or gone: as a full TX queue
            raise can.CanOperationError(f"socket pair send failed: {exc}") from exc

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        waited = not self._pending and not self._receive_batch() and timeout != 0
        if waited and select.select([self._sock], [], [], timeout)[0]:
            self._receive_batch()
        return (self._pending.popleft() if self._pending else None), False

    def _receive_batch(self) -> bool:
        """One datagram's frames onto the pending queue; False when none was waiting."""
        try:
            n = self._sock.recv_into(self._in)
        except (BlockingIOError, InterruptedError):
            return False
        stamp = self._wall_stamp(n)
        if stamp is None:
            return True
        for can_id, length, data in FRAME.iter_unpack(self._in_view[HEADER.size : n]):
            self._pending.append(can.Message(
                timestamp=stamp, arbitration_id=can_id & (0x1FFFFFFF if can_id & EFF else 0x7FF),
                is_extended_id=bool(can_id & EFF), is_remote_frame=bool(can_id & RTR),
                is_error_frame=bool(can_id & ERR), dlc=min(length, 8),
                data=data[: min(length, 8)], channel=self._channel, check=False))  # fmt: skip
        return True

    def _well_formed(self, n: int) -> bool:
        """Whether the datagram of ``n`` bytes in the buffer is a batch of frames (its length
        the layout's, its count its length's); counted when it is not."""
        frames, rest = divmod(n - HEADER.size, FRAME.size)
        if n >= HEADER.size and rest == 0 and HEADER.unpack_from(self._in, 0)[1] == frames:
            return True
        self.malformed += 1
        return False

    def _wall_stamp(self, n: int) -> float | None:
        """The sending instant of the datagram of ``n`` bytes in the buffer, on python-can's
        (wall) clock; None when it is no batch of frames."""
        if not self._well_formed(n):
            return None
        return HEADER.unpack_from(self._in, 0)[0] + (time.time() - time.monotonic())

    # -- the control cycle's path (drivers/transport.py) ----------------------------------------
    def stage(self, msg: can.Message) -> bool:
        """``msg`` into the next ``flush``'s datagram; False if it is full or ``msg`` is a CAN
        FD frame (then nothing is staged)."""
        k = self._staged
        if k >= MAX_FRAMES or msg.is_fd:
            return False
        FRAME.pack_into(self._out, HEADER.size + k * FRAME.size, can_id_of(msg), msg.dlc,
                        bytes(msg.data))  # fmt: skip
        self._staged = k + 1
        return True

    def flush(self) -> int:
        """Every staged frame in one datagram; the number sent (0 when the peer's buffer was
        full or it is gone: the frames dropped, as a full TX queue's). Never raises."""
        n = self._take_staged()
        if n == 0:
            return 0
        HEADER.pack_into(self._out, 0, time.monotonic(), n)
        try:
            self._sock.send(memoryview(self._out)[: HEADER.size + n * FRAME.size])
        except OSError:
            return 0
        return n

    def drain_frames(self) -> Iterator[tuple[int, bool, bytes]]:
        """Every frame waiting now, oldest first, as ``(arbitration id, plain, data)``; ``plain``
        is False for an extended-id, remote or error frame. Never blocks."""
        while self._pending:
            m = self._pending.popleft()
            plain = not (m.is_extended_id or m.is_remote_frame or m.is_error_frame)
            yield m.arbitration_id, plain, bytes(m.data)
        buf, view, recv = self._in, self._in_view, self._sock.recv_into
        while True:
            try:
                n = recv(buf)
            except (BlockingIOError, InterruptedError):
                return
            if not self._well_formed(n):
                continue
            for can_id, length, data in FRAME.iter_unpack(view[HEADER.size : n]):
                size = length if length < 8 else 8
                if can_id & (EFF | RTR | ERR):
                    yield can_id & 0x1FFFFFFF, False, data[:size]
                else:
                    yield can_id & MAX_STANDARD_ID, True, data[:size]

    def shutdown(self) -> None:
        try:
            self._sock.close()
        finally:
            super().shutdown()
