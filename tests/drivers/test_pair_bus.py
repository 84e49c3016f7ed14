"""drivers/pair_bus.py: the socket-pair medium of ``run --sim``'s simulated robot — python-can's
interface for the set-up and the ``canopen`` package, the cycle's batched path, bad datagrams."""

from __future__ import annotations

import socket
import struct
import time

import can
import pytest
from conftest import CONFIG

from drivers.pair_bus import FRAME, HEADER, MAX_FRAMES, PairBus, socket_pair


@pytest.fixture()
def pair():
    a, b = socket_pair()
    ends = PairBus(str(a.detach())), PairBus(str(b.detach()))
    yield ends
    for bus in ends:
        bus.shutdown()


def test_a_frame_crosses_with_every_field_and_its_sending_instant(pair):
    a, b = pair
    frames = [
        can.Message(arbitration_id=0x181, data=b"\x01\x02\x03", is_extended_id=False),
        can.Message(arbitration_id=0x1ABCDEF0 & 0x1FFFFFFF, data=bytes(range(8))),
        can.Message(arbitration_id=0x601, is_remote_frame=True, dlc=2, is_extended_id=False),
        can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False),
    ]
    before = time.time()
    for m in frames:
        a.send(m)
    got = [b.recv(1.0) for _ in frames]
    after = time.time()
    for sent, m in zip(frames, got, strict=True):
        assert m is not None
        assert m.arbitration_id == sent.arbitration_id
        assert m.is_extended_id == sent.is_extended_id
        assert m.is_remote_frame == sent.is_remote_frame
        assert m.dlc == sent.dlc and bytes(m.data) == bytes(sent.data)[: sent.dlc]
        assert before - 1e-3 <= m.timestamp <= after + 1e-3  # python-can's (wall) clock
    assert b.recv(0) is None


def test_recv_waits_for_its_timeout_and_wakes_on_a_frame(pair):
    a, b = pair
    t0 = time.monotonic()
    assert b.recv(0.05) is None
    assert time.monotonic() - t0 >= 0.045
    a.send(can.Message(arbitration_id=0x80, data=b"", is_extended_id=False))
    t0 = time.monotonic()
    assert b.recv(5.0) is not None and time.monotonic() - t0 < 1.0


def test_a_cycles_frames_go_in_one_datagram_and_drain_in_order(pair):
    a, b = pair
    raw = socket.socket(fileno=b.fileno())  # a look at the wire under b's reader
    try:
        for i in range(12):
            assert a.stage(can.Message(arbitration_id=0x200 + i, data=bytes([i] * (i % 9)),
                                       is_extended_id=False))  # fmt: skip
        assert a.staged == 12
        assert a.flush() == 12 and a.staged == 0
        datagram = raw.recv(65536, socket.MSG_PEEK)
        assert len(datagram) == HEADER.size + 12 * FRAME.size
        assert struct.unpack_from("<dI", datagram)[1] == 12
    finally:
        raw.detach()
    drained = list(b.drain_frames())
    assert [d[0] for d in drained] == [0x200 + i for i in range(12)]
    assert all(plain for _, plain, _ in drained)
    assert [d[2] for d in drained] == [bytes([i] * (i % 9)) for i in range(12)]
    assert list(b.drain_frames()) == []


def test_drain_marks_extended_and_remote_frames_not_plain(pair):
    a, b = pair
    a.stage(can.Message(arbitration_id=0x181, data=b"\x00", is_extended_id=True))
    a.stage(can.Message(arbitration_id=0x181, is_remote_frame=True, is_extended_id=False))
    a.stage(can.Message(arbitration_id=0x181, data=b"\x07", is_extended_id=False))
    a.flush()
    assert [(arb, plain) for arb, plain, _ in b.drain_frames()] == [
        (0x181, False), (0x181, False), (0x181, True)]  # fmt: skip


def test_a_full_batch_refuses_the_next_frame_and_fd_frames(pair):
    a, _ = pair
    m = can.Message(arbitration_id=0x300, data=b"", is_extended_id=False)
    assert all(a.stage(m) for _ in range(MAX_FRAMES))
    assert not a.stage(m) and a.staged == MAX_FRAMES
    a.flush()
    assert not a.stage(can.Message(arbitration_id=0x300, is_fd=True, data=bytes(12)))
    with pytest.raises(can.CanOperationError, match="classic CAN frames only"):
        a.send(can.Message(arbitration_id=0x300, is_fd=True, data=bytes(12)))


def test_frames_drained_after_recv_took_their_datagram_are_not_lost(pair):
    """recv (python-can's path) takes a whole datagram; the frames it did not return yet come
    first from drain_frames."""
    a, b = pair
    for i in range(3):
        a.stage(can.Message(arbitration_id=0x100 + i, data=b"", is_extended_id=False))
    a.flush()
    first = b.recv(1.0)
    assert first is not None and first.arbitration_id == 0x100
    assert [arb for arb, _, _ in b.drain_frames()] == [0x101, 0x102]


def test_a_malformed_datagram_is_dropped_and_counted_never_raised(pair):
    a, b = pair
    raw = socket.socket(fileno=a.fileno())
    try:
        raw.send(b"\x00" * 5)  # shorter than a header
        raw.send(HEADER.pack(0.0, 3) + bytes(FRAME.size))  # says 3 frames, holds 1
        raw.send(HEADER.pack(0.0, 1) + bytes(FRAME.size - 1))  # a frame cut short
    finally:
        raw.detach()
    a.send(can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False))
    assert [arb for arb, _, _ in b.drain_frames()] == [0x181]
    assert b.malformed == 3


def test_a_gone_peer_makes_flush_report_nothing_sent(pair):
    a, b = pair
    b.shutdown()
    a.stage(can.Message(arbitration_id=0x181, data=b"", is_extended_id=False))
    assert a.flush() == 0
    with pytest.raises(can.CanOperationError):
        a.send(can.Message(arbitration_id=0x181, data=b"", is_extended_id=False))


def test_the_canopen_package_reads_a_simulated_drives_identity_over_it():
    """An independent CANopen master (the ``canopen`` package, its own Notifier thread on
    python-can's interface) against the simulated drives on the other end of the pair."""
    import canopen

    from cdprctl.robot_file import load_robot
    from sim_backend.network import SimNetwork
    from sim_backend.plant import CdprPlant

    model = load_robot(CONFIG / "rowc.toml")
    ends = [socket_pair() for _ in model.drives.buses]
    ours = [PairBus(str(a.detach())) for a, _ in ends]
    theirs = {"interface": "socketpair", "channels": [str(b.detach()) for _, b in ends]}
    net = SimNetwork(model, CdprPlant(model), theirs)
    network = canopen.Network(ours[0])
    network.connect()
    try:
        node = network.add_node(model.drives.buses[0].node_ids[0], canopen.ObjectDictionary())
        node.sdo.RESPONSE_TIMEOUT = 2.0
        answer: list[bytes] = []
        import threading

        th = threading.Thread(target=lambda: answer.append(node.sdo.upload(0x1018, 4)))
        th.start()
        deadline = time.monotonic() + 5.0
        while th.is_alive() and time.monotonic() < deadline:
            net.advance(0.001)  # the drives answer as time passes
            time.sleep(0.001)
        th.join(5.0)
        serial = int.from_bytes(answer[0], "little")
        assert serial & 0xFFFFFF00 == 0x53494D00  # 'SIM' + node: a simulated drive
    finally:
        network.disconnect()
        net.close()
        for bus in ours[1:]:
            bus.shutdown()
