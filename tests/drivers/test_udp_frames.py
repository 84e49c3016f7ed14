"""The udp_multicast frames packed into slots are python-can's own bytes: compared with
``pack_message`` (python-can's packer, the reference) and read back by ``unpack_message``."""

from __future__ import annotations

import random

import can
import msgpack
import numpy as np
import pytest
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from drivers.udp_frames import ERROR, EXTENDED, FD, REMOTE, FramePacker, template

SLOT = 512


def random_message(rng: random.Random) -> can.Message:
    fd = rng.random() < 0.3
    n = rng.choice([0, 1, 2, 5, 8, 12, 24, 64] if fd else range(9))
    ext = rng.random() < 0.3
    return can.Message(
        timestamp=rng.choice([0.0, rng.uniform(0, 1e5)]),
        arbitration_id=rng.randrange(0x2000_0000 if ext else 0x800),
        is_extended_id=ext,
        is_remote_frame=not fd and n == 0 and rng.random() < 0.2,
        is_error_frame=rng.random() < 0.05,
        channel=rng.choice([None, "can0", 3]),
        data=bytearray(rng.randbytes(n)),
        is_fd=fd,
        bitrate_switch=fd and rng.random() < 0.5,
        error_state_indicator=fd and rng.random() < 0.5,
        check=False,
    )


def slot_bytes(packer: FramePacker, k: int, size: int) -> bytes:
    return bytes(packer.buf[k * SLOT : k * SLOT + size])


def test_every_kind_of_frame_packs_as_python_can_packs_it():
    rng = random.Random(64)
    packer = FramePacker(4, SLOT)
    messages = [random_message(rng) for _ in range(300)]
    for i in range(3000):  # slots reused by other kinds, data changed in place
        msg = messages[rng.randrange(len(messages))]
        msg.data[:] = rng.randbytes(len(msg.data))
        k = i % 4
        size = packer.pack(k, msg)
        assert slot_bytes(packer, k, size) == pack_message(msg)
    back = unpack_message(slot_bytes(packer, k, size))
    assert back.arbitration_id == msg.arbitration_id and back.data == msg.data


def test_a_field_changed_in_place_gives_another_template():
    packer = FramePacker(1, SLOT)
    msg = can.Message(arbitration_id=0x201, data=bytearray(8), is_extended_id=False)
    packer.pack(0, msg)
    msg.arbitration_id = 0x202
    msg.data = bytearray(b"\x01\x02")
    msg.dlc = 2
    size = packer.pack(0, msg)
    assert slot_bytes(packer, 0, size) == pack_message(msg)


def test_data_of_any_length_lies_where_the_template_says():
    for n in range(9):
        msg = can.Message(arbitration_id=0x181, data=bytearray(range(1, n + 1)))
        tpl = template(msg)
        assert tpl is not None
        head, o, tail, total = tpl
        packed = pack_message(msg)
        assert packed == head + bytes(msg.data) + tail and len(packed) == total
        assert len(head) == o


def test_a_frame_too_big_for_its_slot_is_refused_and_the_slot_kept():
    packer = FramePacker(1, 100)  # a classic frame needs ~162 bytes
    msg = can.Message(arbitration_id=0x181, data=bytearray(8))
    assert packer.pack(0, msg) == 0
    assert not any(packer.buf)


@pytest.mark.parametrize("channel", [["a", "list"], {"not": "hashable"}])
def test_a_frame_of_no_template_is_packed_whole(channel):
    packer = FramePacker(1, SLOT)
    msg = can.Message(arbitration_id=0x181, data=bytearray(b"\x01"), check=False)
    msg.channel = channel
    size = packer.pack(0, msg)
    assert slot_bytes(packer, 0, size) == pack_message(msg)


def expected(raw: bytes) -> tuple[int, int, bytes] | None:
    """What a datagram says, by msgpack's own unpacker (the reference): (id, flags, data), or
    None for what is no frame."""
    try:
        d = msgpack.unpackb(raw)
        arb, data = d["arbitration_id"], d["data"]
        flags = sum(bit for key, bit in (("is_extended_id", EXTENDED), ("is_remote_frame", REMOTE),
                                         ("is_error_frame", ERROR), ("is_fd", FD))
                    if d.get(key, False))  # fmt: skip
        # the flags as the cycle has always read them: a later one only if the earlier are off
        d["is_extended_id"] or d["is_remote_frame"] or d["is_error_frame"]
    except Exception:
        return None
    if type(arb) is not int or type(data) is not bytes or arb < 0:
        return None
    return arb, flags, data


def variants(rng: random.Random) -> list[bytes]:
    """python-can's datagrams and their neighbours: fields shuffled, unknown ones added, one
    missing, of another type, a map16, truncated, trailing bytes, no map at all."""
    out = []
    for _ in range(400):
        msg = random_message(rng)
        d = msgpack.unpackb(pack_message(msg))
        out.append(pack_message(msg))
        items = list(d.items())
        rng.shuffle(items)
        kind = rng.randrange(8)
        if kind == 0:
            items.append(("extra", rng.choice([None, 1.5, "x", -3, 2**40, b"zz"])))
        elif kind == 1:
            del items[rng.randrange(len(items))]
        elif kind == 2:
            k = rng.randrange(len(items))
            items[k] = (items[k][0], rng.choice(["0x181", -1, 2**64 - 1, [1], {"a": 1}, 1.0]))
        elif kind == 3:
            items += [(f"pad{j}", j) for j in range(10)]  # 16 and more: a map16
        raw = msgpack.packb(dict(items), use_bin_type=True)
        if kind == 4:
            raw = raw[: rng.randrange(len(raw))]
        elif kind == 5:
            raw += b"\x00"
        elif kind == 6:
            raw = msgpack.packb([1, 2, 3])
        out.append(raw)
    return out


def test_the_kernel_reads_what_msgpack_reads_or_leaves_it_to_msgpack():
    from drivers.udp_frames import FRAME, KEY_BYTES, decode_frames_kernel

    rng = random.Random(65)
    datagrams = variants(rng)
    stride = 512
    buf = np.zeros(len(datagrams) * stride, dtype=np.uint8)
    sizes = np.zeros(len(datagrams), dtype=np.uint32)
    for i, raw in enumerate(datagrams):
        buf[i * stride : i * stride + len(raw)] = np.frombuffer(raw, dtype=np.uint8)
        sizes[i] = len(raw)
    out = np.zeros((len(datagrams), 5), dtype=np.int64)
    decode_frames_kernel(buf, stride, sizes, len(datagrams), KEY_BYTES, out)
    read = 0
    for i, raw in enumerate(datagrams):
        want = expected(raw)
        if out[i, 0] != FRAME:
            continue  # msgpack's own unpacker reads it (the bus's fallback)
        read += 1
        arb, flags, off, n = (int(x) for x in out[i, 1:])
        assert want == (arb, flags, bytes(buf[off : off + n])), raw
    # every frame python-can packs is read by the kernel, not left to msgpack
    assert all(out[i, 0] == FRAME for i in range(0, 800, 2))
    assert read > 450


def test_the_bus_drains_every_datagram_as_msgpack_reads_it():
    """The same datagrams sent on a group: what ``drain_frames`` gives, kernel and fallback
    together, is what msgpack's unpacker says (FD frames dropped on a classic bus)."""
    import os
    import socket
    import time

    from drivers.udp_bus import CyclicUdpMulticastBus

    group, port = "239.74.163.2", random.Random(os.getpid() * 41).randrange(40000, 50000)
    datagrams = variants(random.Random(66))[:200]
    bus = CyclicUdpMulticastBus(group, port=port, fd=False)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
    try:
        got: list = []
        for k in range(0, len(datagrams), 20):  # within the socket's buffer
            for raw in datagrams[k : k + 20]:
                tx.sendto(raw, (group, port))
            time.sleep(0.02)
            got.extend(bus.drain_frames())
    finally:
        tx.close()
        bus.shutdown()
    want = []
    for raw in datagrams:
        e = expected(raw)
        if e is not None and not e[1] & FD:
            want.append((e[0], not e[1] & (EXTENDED | REMOTE | ERROR) and e[0] <= 0x7FF, e[2]))
    assert got == want
    assert bus.malformed == sum(expected(raw) is None for raw in datagrams)
