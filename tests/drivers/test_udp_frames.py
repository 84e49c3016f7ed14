"""The udp_multicast frames packed into slots are python-can's own bytes: compared with
``pack_message`` (python-can's packer, the reference) and read back by ``unpack_message``."""

from __future__ import annotations

import random

import can
import pytest
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from drivers.udp_frames import FramePacker, template

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
