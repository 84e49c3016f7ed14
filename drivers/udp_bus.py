"""python-can's ``udp_multicast`` bus with a cyclic path: reads that build no ``can.Message``,
a cycle's frames sent in one system call.

python-can's ``recv(0)`` costs a ``select``, a ``recvmsg``, a msgpack decode and a checked
``Message`` per frame, and ``udp_multicast`` loops every frame we send back to us: across
processes the driver's read phase spent most of its time there. Its ``send`` is one ``sendto``
per frame, and each wakes the peer blocked on the group again (on this VM a cycle's 9 frames
cost ~4x one ``sendmmsg`` of them: ``benchmarks/bench_udp_medium.py``). This bus is
python-can's own (same socket, same wire format: any python-can peer talks to it) plus
``drain_frames`` — every waiting datagram by non-blocking ``recv`` on the same socket until
none is left, decoded to ``(arbitration id, plain, data)`` — and ``stage``/``flush``: frames
packed as python-can packs them, sent together by ``sendmmsg`` (Linux; elsewhere one
``sendto`` each) from a send socket connected to the group. The set-up (SDO, NMT, the
``canopen`` package) keeps python-can's path through ``recv``/``send``.

Two differences from python-can's defaults, both for a medium that stands in for vcan on one
machine (``docs/drivers.md``): the hop limit is 0 unless given (``--can-option hop_limit=1``
for peers on other machines), so a frame never leaves the machine — with python-can's 1 each
one also went out on the NIC, on this VM a transmit to the host per frame, half of a cycle's
write across processes; and the receive socket drops what our own ``flush`` sent (python-can's
bus has no ``receive_own_messages`` either, but the loopback gave it them: half the frames a
cycle read across processes were our own).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import socket
import struct
from collections.abc import Iterator
from typing import Any

import can
import msgpack
import numpy as np
from can.interfaces.udp_multicast import UdpMulticastBus
from can.interfaces.udp_multicast.utils import pack_message

from drivers.cyclic_path import StagedFrames
from drivers.udp_frames import (
    ERROR,
    EXTENDED,
    FD,
    FRAME,
    KEY_BYTES,
    REMOTE,
    FramePacker,
    decode_frames_kernel,
)

HOST_LOCAL_HOPS = 0  # hop limit unless given: the frames stay on this machine
MAX_DATAGRAM = 4096  # bytes: python-can's own receive buffer
RX_SLOTS = 32  # datagrams one recvmmsg reads at most (a cycle of rowc: 8-9)
MAX_STANDARD_ID = 0x7FF
MAX_STAGED = 64  # frames a flush sends at most in one call (a cycle of rowc: 9-17)
SLOT_BYTES = 512  # a packed frame: 162 bytes classic, 218 CAN FD


class _Iovec(ctypes.Structure):
    _fields_ = [("base", ctypes.c_void_p), ("len", ctypes.c_size_t)]


class _Msghdr(ctypes.Structure):  # struct msghdr (Linux)
    _fields_ = [
        ("name", ctypes.c_void_p),
        ("namelen", ctypes.c_uint32),
        ("iov", ctypes.POINTER(_Iovec)),
        ("iovlen", ctypes.c_size_t),
        ("control", ctypes.c_void_p),
        ("controllen", ctypes.c_size_t),
        ("flags", ctypes.c_int),
    ]


class _Mmsghdr(ctypes.Structure):
    _fields_ = [("hdr", _Msghdr), ("len", ctypes.c_uint)]


def _libc(name: str) -> Any:
    """libc's ``sendmmsg(fd, msgvec, vlen, flags)`` or ``recvmmsg(fd, msgvec, vlen, flags,
    timeout)``, or None where there is none."""
    try:
        fn = getattr(ctypes.CDLL(None, use_errno=True), name)
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_uint, ctypes.c_int]
    if name == "recvmmsg":
        fn.argtypes.append(ctypes.c_void_p)
    fn.restype = ctypes.c_int
    return fn


def _vectors(address: int, slots: int, slot_bytes: int) -> Any:
    """``slots`` message headers (``struct mmsghdr``), header i over ``slot_bytes`` bytes at
    ``address + i * slot_bytes``."""
    iov = (_Iovec * slots)()
    hdrs = (_Mmsghdr * slots)()
    for i in range(slots):
        iov[i].base = address + i * slot_bytes
        iov[i].len = slot_bytes
        hdrs[i].hdr.iov = ctypes.pointer(iov[i])
        hdrs[i].hdr.iovlen = 1
    return iov, hdrs


class _Receiver:
    """The receive side of ``drain_frames``: up to ``RX_SLOTS`` datagrams a ``recvmmsg`` into
    one buffer, read there by a kernel (``udp_frames.decode_frames_kernel``)."""

    def __init__(self, recvmmsg: Any):
        self.recvmmsg = recvmmsg
        self.buf = bytearray(RX_SLOTS * MAX_DATAGRAM)
        self._pin = ctypes.c_char.from_buffer(self.buf)  # never resized while the kernel writes
        self.array = np.frombuffer(self.buf, dtype=np.uint8)
        self.view = memoryview(self.buf)
        self._iov, self.hdrs = _vectors(ctypes.addressof(self._pin), RX_SLOTS, MAX_DATAGRAM)
        self.hdrs_at = ctypes.addressof(self.hdrs)
        words = ctypes.sizeof(_Mmsghdr) // 4  # each header's received length, as an array
        lengths = np.ctypeslib.as_array(
            (ctypes.c_uint32 * (RX_SLOTS * words)).from_buffer(self.hdrs)
        )
        self.sizes = lengths[_Mmsghdr.len.offset // 4 :: words]
        self.out = np.zeros((RX_SLOTS, 5), dtype=np.int64)
        self.fields = self.out.reshape(-1).data  # read as Python ints, no numpy scalar
        self.keys = KEY_BYTES
        decode_frames_kernel(self.array, MAX_DATAGRAM, self.sizes, 0, self.keys, self.out)


# Linux's <linux/in.h> IP_MULTICAST_ALL and <linux/in6.h> IPV6_MULTICAST_ALL (Python names
# neither): 0 delivers a socket only the groups it joined itself
IP_MULTICAST_ALL = 49
IPV6_MULTICAST_ALL = 29


def _own_group_only(sock: socket.socket) -> None:
    """Only the datagrams of the group this socket joined. python-can binds its socket to the
    port on every address, and Linux then delivers it the datagrams of every group that any
    socket of the machine joined on that port (IP_MULTICAST_ALL is 1 by default): two
    simulated robots on groups .97 and .98 of one port heard each other's node ids 1-8. With
    it 0, a channel (group and port) is one robot. Elsewhere, where there is no such option,
    nothing changes (give each robot its own port there)."""
    v6 = sock.family == socket.AF_INET6
    with contextlib.suppress(OSError):
        sock.setsockopt(socket.IPPROTO_IPV6 if v6 else socket.IPPROTO_IP,
                        IPV6_MULTICAST_ALL if v6 else IP_MULTICAST_ALL, 0)  # fmt: skip


# Linux's socket filter (<linux/filter.h>): classic BPF over the datagram, offset 0 its UDP
# header, SKF_NET_OFF + k the IP header's byte k
SO_ATTACH_FILTER = 26
SKF_NET_OFF = -0x100000
_LD_H_ABS, _LD_W_ABS, _JEQ_K, _RET_K = 0x28, 0x20, 0x15, 0x06


def _own_datagrams_dropped(rx: socket.socket, tx: socket.socket) -> bool:
    """Make ``rx`` drop the datagrams ``tx`` sends (their source: ``tx``'s address and port,
    which no other socket of this machine has), in the kernel, before they are queued; every
    other sender's datagrams pass. False where the kernel has no socket filter (then our own
    frames keep arriving: ``drain_frames`` reads and ignores them as before)."""
    host, port = tx.getsockname()[:2]
    v6 = tx.family == socket.AF_INET6
    address = socket.inet_pton(tx.family, host.split("%")[0])
    words = struct.unpack(f"!{len(address) // 4}I", address)
    source_at = (8 if v6 else 12) + SKF_NET_OFF  # the IP header's source address
    n = len(words)
    # ldh [0] (UDP source port); jeq port; then each word of the source address; a mismatch
    # jumps to "keep" (the last instruction), all matching falls through to "drop"
    prog = [(_LD_H_ABS, 0, 0, 0), (_JEQ_K, 0, 2 * n + 1, port)]
    for i, w in enumerate(words):
        prog += [(_LD_W_ABS, 0, 0, (source_at + 4 * i) & 0xFFFFFFFF),
                 (_JEQ_K, 0, 2 * (n - i) - 1, w)]  # fmt: skip
    prog += [(_RET_K, 0, 0, 0), (_RET_K, 0, 0, 0xFFFFFFFF)]
    code = ctypes.create_string_buffer(b"".join(struct.pack("HBBI", *op) for op in prog))
    fprog = struct.pack("HL", len(prog), ctypes.addressof(code))  # struct sock_fprog
    try:
        rx.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, fprog)
    except OSError:
        return False
    return True


class CyclicUdpMulticastBus(StagedFrames, UdpMulticastBus):
    """``UdpMulticastBus`` (same arguments) with the control cycle's path: ``drain_frames``
    to read, ``stage`` and ``flush`` to send."""

    def __init__(self, channel: str = UdpMulticastBus.DEFAULT_GROUP_IPv4, **kwargs: Any):
        kwargs.setdefault("hop_limit", HOST_LOCAL_HOPS)
        super().__init__(channel, **kwargs)
        # A second handle on the same socket (its receive queue, its options): reading it by
        # MSG_DONTWAIT never changes the blocking mode python-can's send relies on.
        self._raw = socket.socket(fileno=os.dup(self.fileno()))
        _own_group_only(self._raw)
        self._unpack = msgpack.unpackb
        self._fd_frames = self.protocol is can.CanProtocol.CAN_FD
        #: datagrams that were no python-can frame (not msgpack, a field missing or of the wrong
        #: type): dropped like a frame with a bad CRC on a wire, never raised in the cycle
        self.malformed = 0
        recvmmsg = _libc("recvmmsg")
        self._rx = _Receiver(recvmmsg) if recvmmsg is not None else None
        self._open_sender(channel, int(kwargs.get("port", 43113)), int(kwargs["hop_limit"]))
        #: our own flushed frames are dropped by the kernel, not read back (a socket filter)
        self.own_frames_dropped = _own_datagrams_dropped(self._raw, self._tx)

    def _open_sender(self, group: str, port: int, hop_limit: int) -> None:
        """A socket connected to the group for ``flush`` (no address per datagram; the group's
        members, this bus's own socket included, receive as from python-can's ``send``), and
        the preallocated batch: one buffer and one header per slot."""
        family = socket.getaddrinfo(group, port, type=socket.SOCK_DGRAM)[0][0]
        self._tx = socket.socket(family, socket.SOCK_DGRAM)
        hops = struct.pack("@I", hop_limit)
        if family == socket.AF_INET:
            self._tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, hops)
        else:
            self._tx.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_MULTICAST_HOPS, hops)
        self._tx.connect((group, port))
        self._sendmmsg = _libc("sendmmsg")
        self._packer = FramePacker(MAX_STAGED, SLOT_BYTES)
        self._iov, self._hdrs = _vectors(self._packer.address, MAX_STAGED, SLOT_BYTES)
        self._iov_of = [self._iov[i] for i in range(MAX_STAGED)]  # views, made once
        self._staged = 0
        self._datagrams: list[bytes] = []  # without sendmmsg: sent one by one

    def stage(self, msg: can.Message) -> bool:
        """Pack ``msg`` now (the bytes python-can's ``send`` sends: ``udp_frames.py``) for the
        next ``flush``; False if the batch is full or the frame does not fit a slot (then
        nothing is staged)."""
        k = self._staged
        if k >= MAX_STAGED:
            return False
        if self._sendmmsg is None:
            data = pack_message(msg)
            if len(data) > SLOT_BYTES:
                return False
            self._datagrams.append(data)
        else:
            size = self._packer.pack(k, msg)
            if size == 0:
                return False
            self._iov_of[k].len = size
        self._staged = k + 1
        return True

    def flush(self) -> int:
        """Send every staged frame, in order, in one ``sendmmsg``; the number sent (the rest,
        after a send that failed — a full socket buffer, like a full TX queue — are dropped).
        Never raises."""
        n = self._take_staged()
        if n == 0:
            return 0
        if self._sendmmsg is None:
            sent = 0
            try:
                for d in self._datagrams:
                    self._tx.send(d, socket.MSG_DONTWAIT)
                    sent += 1
            except OSError:
                pass
            self._datagrams.clear()
            return sent
        sent = self._sendmmsg(
            self._tx.fileno(), ctypes.addressof(self._hdrs), n, socket.MSG_DONTWAIT
        )
        return max(0, sent)

    def drain_frames(self) -> Iterator[tuple[int, bool, bytes]]:
        """Every frame waiting now, oldest first, as ``(arbitration id, plain, data)``; ``plain``
        is False for an extended-id, remote or error frame. Never blocks; ignores the software
        filters (the driver dispatches by id itself). By ``recvmmsg`` and a kernel where there
        is one: no ``recv`` and no dict of eleven fields per frame."""
        rx = self._rx
        if rx is None:
            recv = self._raw.recv
            while True:
                try:
                    raw = recv(MAX_DATAGRAM, socket.MSG_DONTWAIT)
                except (BlockingIOError, InterruptedError):
                    return
                frame = self._frame_of(raw)
                if frame is not None:
                    yield frame
        fd, fields, view = self._raw.fileno(), rx.fields, rx.view
        while True:
            n = rx.recvmmsg(fd, rx.hdrs_at, RX_SLOTS, socket.MSG_DONTWAIT, None)
            if n <= 0:
                return
            decode_frames_kernel(rx.array, MAX_DATAGRAM, rx.sizes, n, rx.keys, rx.out)
            for i in range(n):
                k = 5 * i
                if fields[k] != FRAME:  # python-can's unpacker decides
                    frame = self._frame_of(view[i * MAX_DATAGRAM : i * MAX_DATAGRAM + rx.sizes[i]])
                    if frame is not None:
                        yield frame
                    continue
                arb, flags, off = fields[k + 1], fields[k + 2], fields[k + 3]
                if flags & FD and not self._fd_frames:
                    continue  # python-can drops these too on a classic bus
                plain = not flags & (EXTENDED | REMOTE | ERROR) and arb <= MAX_STANDARD_ID
                yield arb, plain, bytes(view[off : off + fields[k + 4]])
            if n < RX_SLOTS:
                return

    def _frame_of(self, raw: Any) -> tuple[int, bool, bytes] | None:
        """A datagram as ``drain_frames`` gives it, unpacked by msgpack as python-can does;
        None for one that is no frame (counted in ``malformed``) or an FD frame on a classic
        bus."""
        try:
            d = self._unpack(raw)
            arb = d["arbitration_id"]
            data = d["data"]
            plain = not (d["is_extended_id"] or d["is_remote_frame"] or d["is_error_frame"])
            fd = d.get("is_fd", False)
        except Exception:  # anything on the group that is not a frame: dropped, counted
            arb = data = None
        if type(arb) is not int or type(data) is not bytes or arb < 0:
            self.malformed += 1
            return None
        if fd and not self._fd_frames:
            return None  # python-can drops these too on a classic bus
        return arb, plain and arb <= MAX_STANDARD_ID, data

    def shutdown(self) -> None:
        try:
            self._raw.close()
            self._tx.close()
        finally:
            super().shutdown()
