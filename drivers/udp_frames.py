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
from can.interfaces.udp_multicast.utils import pack_message

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
