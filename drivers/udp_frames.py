"""python-can's ``udp_multicast`` wire format written into preallocated slots without a dict
and a ``msgpack.packb`` per frame: the bytes around a frame's data are the same every cycle.

python-can's ``pack_message`` builds a dict of the frame's eleven fields and packs it, ~3 µs a
frame here; a cycle sends 9-17. ``FramePacker`` packs a kind of frame (every field but the
data's bytes) once by ``pack_message`` itself, finds where the data lies in it, and from then
on copies only the data into a slot that already holds the rest: the same bytes, any python-can
peer reads them (tests/drivers/test_udp_frames.py compares them with ``pack_message``'s).
"""

from __future__ import annotations

import copy
import ctypes
from typing import Any

import can
import numpy as np
from can.interfaces.udp_multicast.utils import pack_message

from cdprctl.core.numerics import cycle_kernel

TEMPLATES_MAX = 256  # kinds of frame remembered (a cycle sends a few: RPDOs, SYNC, heartbeat)


def frame_kind(msg: can.Message) -> tuple[Any, ...]:
    """Every field ``pack_message`` packs but the data's bytes (their number instead)."""
    return (msg.timestamp, msg.arbitration_id, msg.is_extended_id, msg.is_remote_frame,
            msg.is_error_frame, msg.channel, msg.dlc, len(msg.data), msg.is_fd,
            msg.bitrate_switch, msg.error_state_indicator)  # fmt: skip


def template(msg: can.Message) -> tuple[bytes, int, bytes, int] | None:
    """(the bytes before the data, their length, the bytes after it, the datagram's length)
    of ``msg``'s kind, found by packing it with its data all 0x00 and all 0xFF: the two differ
    in exactly the data's bytes. None when they differ anywhere else (a format that does not
    hold the data as it is): such a frame is packed whole each time."""
    n = len(msg.data)
    probe = copy.copy(msg)
    probe.data = bytearray(n)
    zeros = pack_message(probe)
    probe.data = bytearray(b"\xff" * n)
    ones = pack_message(probe)
    if len(zeros) != len(ones):
        return None
    if n == 0:
        return (zeros, len(zeros), b"", len(zeros)) if zeros == ones else None
    differ = [i for i, (a, b) in enumerate(zip(zeros, ones, strict=True)) if a != b]
    o = differ[0] if differ else -1
    if differ != list(range(o, o + n)) or ones[o : o + n] != b"\xff" * n:
        return None
    return zeros[:o], o, zeros[o + n :], len(zeros)


class FramePacker:
    """``slots`` datagrams of at most ``slot_bytes`` each in one buffer (``address``: where
    it starts, for a system call's vectors), packed as python-can packs them."""

    def __init__(self, slots: int, slot_bytes: int):
        self.slot_bytes = slot_bytes
        self.buf = bytearray(slots * slot_bytes)
        # a ctypes view pins the buffer: a write of the wrong length raises, never resizes it
        self._pin = ctypes.c_char.from_buffer(self.buf)
        self.address = ctypes.addressof(self._pin)
        self._templates: dict[tuple[Any, ...], tuple[bytes, int, bytes, int] | None] = {}
        self._in_slot: list[tuple[bytes, int, bytes, int] | None] = [None] * slots

    def pack(self, k: int, msg: can.Message) -> int:
        """``msg`` packed into slot ``k``; its length in bytes, 0 if it does not fit (then the
        slot is unchanged)."""
        try:
            kind = frame_kind(msg)
            tpl = self._templates[kind]
        except KeyError:
            if len(self._templates) >= TEMPLATES_MAX:
                self._templates.clear()
            tpl = self._templates[kind] = template(msg)
        except TypeError:  # a field that cannot be a key (an unhashable channel)
            tpl = None
        s, buf = k * self.slot_bytes, self.buf
        if tpl is None:
            whole = pack_message(msg)
            if len(whole) > self.slot_bytes:
                return 0
            buf[s : s + len(whole)] = whole
            self._in_slot[k] = None
            return len(whole)
        head, o, tail, total = tpl
        if total > self.slot_bytes:
            return 0
        data = msg.data
        if self._in_slot[k] is not tpl:  # the slot held another kind: its bytes around the data
            buf[s : s + o] = head
            buf[s + total - len(tail) : s + total] = tail
            self._in_slot[k] = tpl
        buf[s + o : s + o + len(data)] = data
        return total


# What ``decode_frames_kernel`` says of a datagram (``out[i, 0]``)
FRAME, OTHER = 1, 0  # a frame it read; anything else (python-can's unpacker decides)
# ``out[i, 2]``'s bits: the frame's flags
EXTENDED, REMOTE, ERROR, FD = 1, 2, 4, 8
_KEYS = {  # the fields the cycle reads: their key's bytes, and what each is
    b"arbitration_id": 1, b"data": 2, b"is_extended_id": 3, b"is_remote_frame": 4,
    b"is_error_frame": 5, b"is_fd": 6,
}  # fmt: skip
KEY_BYTES = np.zeros((len(_KEYS), 16), dtype=np.uint8)  # zero-padded, length in column 15
for _i, _k in enumerate(_KEYS):
    KEY_BYTES[_i, : len(_k)] = np.frombuffer(_k, dtype=np.uint8)
    KEY_BYTES[_i, 15] = len(_k)


@cycle_kernel
def _key_of(buf, p, n, keys):  # pragma: no cover - compiled
    """Which of ``keys`` the ``n`` bytes at ``buf[p]`` are (its row + 1), 0 for none."""
    for r in range(keys.shape[0]):
        if keys[r, 15] != n:
            continue
        same = True
        for j in range(n):
            if buf[p + j] != keys[r, j]:
                same = False
                break
        if same:
            return r + 1
    return 0


@cycle_kernel
def _value(buf, p, end):  # pragma: no cover - compiled
    """(kind, value, where its bytes start, where the next item starts) of the msgpack item at
    ``p``: kind 1 an integer >= 0 (value), 2 a boolean (value 0/1), 3 bytes (value: their
    length), 4 anything else scalar (skipped), -1 what this does not read (an array, a map, an
    extension, a negative integer or one beyond int64, bytes past ``end``)."""
    b = np.int64(buf[p])
    if b <= 0x7F:
        return 1, b, p, p + 1
    if b == 0xC2 or b == 0xC3:
        return 2, b - 0xC2, p, p + 1
    if b == 0xC0:
        return 4, 0, p, p + 1
    if 0xCC <= b <= 0xCF:  # uint 8/16/32/64, big-endian
        size = np.int64(1) << (b - 0xCC)
        if p + 1 + size > end or (size == 8 and buf[p + 1] >= 0x80):
            return -1, 0, p, end
        v = np.int64(0)
        for j in range(size):
            v = (v << 8) | np.int64(buf[p + 1 + j])
        return 1, v, p, p + 1 + size
    if b == 0xCA or b == 0xCB:  # float 32/64
        return 4, 0, p, p + (5 if b == 0xCA else 9)
    if 0xA0 <= b <= 0xBF or 0xD9 <= b <= 0xDB or 0xC4 <= b <= 0xC6:  # str or bin
        if 0xA0 <= b <= 0xBF:
            size, head = np.int64(0), b & 0x1F
        else:
            size = np.int64(1) << ((b - 0xD9) if b >= 0xD9 else (b - 0xC4))
            if p + 1 + size > end:
                return -1, 0, p, end
            head = np.int64(0)
            for j in range(size):
                head = (head << 8) | np.int64(buf[p + 1 + j])
        start = p + 1 + size
        if start + head > end:
            return -1, 0, p, end
        return (3 if 0xC4 <= b <= 0xC6 else 4), head, start, start + head
    return -1, 0, p, end


@cycle_kernel
def decode_frames_kernel(buf, stride, sizes, n, keys, out):  # pragma: no cover - compiled
    """The ``n`` datagrams at ``buf[i * stride]`` (``sizes[i]`` bytes each) read as python-can
    packs a frame (a msgpack map; its fields in any order): ``out[i]`` = (FRAME, arbitration
    id, flags, data offset in ``buf``, data length), or OTHER when it is not such a map or
    lacks a field (python-can's own unpacker then decides: ``CyclicUdpMulticastBus``)."""
    for i in range(n):
        out[i, 0] = OTHER
        p, end = i * stride, i * stride + sizes[i]
        if p >= end:
            continue
        b = np.int64(buf[p])
        if 0x80 <= b <= 0x8F:
            count, p = b & 0x0F, p + 1
        elif b == 0xDE and p + 3 <= end:
            count, p = (np.int64(buf[p + 1]) << 8) | np.int64(buf[p + 2]), p + 3
        else:
            continue
        arb, flags, off, size, seen, ok = np.int64(-1), np.int64(0), p, np.int64(-1), 0, True
        for _ in range(count):
            if p >= end or not 0xA0 <= buf[p] <= 0xBF:  # a key: a short string
                ok = False
                break
            klen = np.int64(buf[p] & 0x1F)
            if p + 1 + klen >= end:
                ok = False
                break
            key = _key_of(buf, p + 1, klen, keys)
            kind, v, start, p = _value(buf, p + 1 + klen, end)
            if kind < 0:
                ok = False
                break
            if key == 1 and kind == 1:
                arb = v
            elif key == 2 and kind == 3:
                off, size = start, v
            elif key >= 3 and kind == 2:
                bit = np.int64(1) << (key - 3)
                flags = (flags | bit) if v else (flags & ~bit)
            elif key != 0:
                ok = False  # a field the cycle reads, of another type
                break
            if key != 0:
                seen |= 1 << key
        if ok and p == end and seen & 0b111110 == 0b111110:
            out[i, 0], out[i, 1], out[i, 2], out[i, 3], out[i, 4] = FRAME, arb, flags, off, size
