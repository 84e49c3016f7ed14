"""The cyclic udp_multicast bus against python-can's own UdpMulticastBus on the same group: the
same frames both ways, and a datagram that is no frame dropped and counted, never raised."""

from __future__ import annotations

import os
import random
import socket
import threading
import time

import can
import msgpack
import pytest
from can.interfaces.udp_multicast import UdpMulticastBus
from conftest import CONFIG

from cdprctl.model.drives import BusConfig
from drivers.buses import open_bus
from drivers.udp_bus import CyclicUdpMulticastBus

GROUP = "239.74.163.2"


@pytest.fixture
def pair():
    port = random.Random(os.getpid() * 13).randrange(40000, 50000)
    ours = CyclicUdpMulticastBus(GROUP, port=port, fd=False)
    theirs = UdpMulticastBus(GROUP, port=port, fd=True)
    try:
        yield ours, theirs, port
    finally:
        ours.shutdown()
        theirs.shutdown()


def drained(bus: CyclicUdpMulticastBus, n: int, timeout: float = 5.0) -> list:
    """The first ``n`` frames ``drain_frames`` gives (multicast loopback is delivered within the
    sender's syscall; the deadline is only for a loaded machine)."""
    got: list = []
    deadline = time.monotonic() + timeout
    while len(got) < n and time.monotonic() < deadline:
        got.extend(bus.drain_frames())
    return got


def test_frames_from_python_can_arrive_decoded(pair):
    ours, theirs, _ = pair
    sent = [
        can.Message(arbitration_id=0x181, data=bytes(range(8)), is_extended_id=False),
        can.Message(arbitration_id=0x80, data=b"\x07", is_extended_id=False),
        can.Message(arbitration_id=0x701, data=b"", is_extended_id=False),
        can.Message(arbitration_id=0x181, data=b"\x01\x02", is_extended_id=True),
        can.Message(arbitration_id=0x181, is_remote_frame=True, dlc=8, is_extended_id=False),
        can.Message(arbitration_id=0x1234567, data=b"\x05", is_extended_id=True),
    ]
    for msg in sent:
        theirs.send(msg)
    got = drained(ours, len(sent))
    assert got == [
        (0x181, True, bytes(range(8))),
        (0x80, True, b"\x07"),
        (0x701, True, b""),
        (0x181, False, b"\x01\x02"),  # extended: not one of a CANopen drive's ids
        (0x181, False, b""),  # remote
        (0x1234567, False, b"\x05"),
    ]
    assert list(ours.drain_frames()) == []  # drained: the next call finds nothing


def test_frames_we_send_reach_python_can(pair):
    ours, theirs, _ = pair
    msg = can.Message(arbitration_id=0x201, data=bytearray(b"\x0f\x00\x10\x27\x00\x00\x00\x00"))
    msg.is_extended_id = False
    ours.send(msg, timeout=0)
    got = theirs.recv(5.0)
    assert got is not None
    assert got.arbitration_id == 0x201 and not got.is_extended_id
    assert bytes(got.data) == bytes(msg.data) and got.dlc == 8
    # the set-up path (SDO, NMT, canopen) still reads through python-can's recv
    theirs.send(can.Message(arbitration_id=0x581, data=b"\x60\x40\x60\x00\x00\x00\x00\x00"))
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        back = ours.recv(0.5)
        if back is not None and back.arbitration_id == 0x581:
            break
    else:
        pytest.fail("python-can's frame never reached the cyclic bus's recv")
    assert bytes(back.data) == b"\x60\x40\x60\x00\x00\x00\x00\x00"


def test_datagrams_that_are_no_frame_are_dropped_and_counted(pair):
    ours, theirs, port = pair
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        junk = [
            b"\xc1not msgpack",  # 0xc1 is never used by msgpack
            msgpack.packb({"arbitration_id": 0x181}),  # fields missing
            msgpack.packb(
                {
                    "arbitration_id": "0x181",  # a string id
                    "data": b"12345678",
                    "is_extended_id": False,
                    "is_remote_frame": False,
                    "is_error_frame": False,
                }
            ),
            msgpack.packb([1, 2, 3]),  # not a map
        ]
        for d in junk:
            raw.sendto(d, (GROUP, port))
    finally:
        raw.close()
    theirs.send(can.Message(arbitration_id=0x181, data=b"\x01", is_extended_id=False))
    got = drained(ours, 1)
    assert got == [(0x181, True, b"\x01")]
    assert ours.malformed == len(junk)


def test_fd_frames_are_dropped_on_a_classic_bus(pair):
    ours, theirs, _ = pair
    theirs.send(can.Message(arbitration_id=0x181, data=bytes(12), is_fd=True))
    theirs.send(can.Message(arbitration_id=0x182, data=b"\x02", is_extended_id=False))
    assert drained(ours, 1) == [(0x182, True, b"\x02")]


def test_drain_never_blocks_even_on_a_blocking_socket(pair):
    ours, _, _ = pair
    socket.socket(fileno=os.dup(ours.fileno())).settimeout(None)  # shared file: blocking
    done = threading.Event()

    def drain() -> None:
        list(ours.drain_frames())
        done.set()

    th = threading.Thread(target=drain, daemon=True)
    th.start()
    assert done.wait(10.0), "drain_frames blocked on an empty socket"


def test_open_bus_gives_the_cyclic_bus_for_udp_multicast():
    port = random.Random(os.getpid() * 17).randrange(40000, 50000)
    cfg = BusConfig("udp_multicast", GROUP, 1_000_000, (0,), (1,))
    bus = open_bus(cfg, {"options": {"port": port}})
    try:
        assert isinstance(bus, CyclicUdpMulticastBus)
    finally:
        bus.shutdown()


def received(bus: UdpMulticastBus, n: int, timeout: float = 5.0) -> list[can.Message]:
    got: list[can.Message] = []
    deadline = time.monotonic() + timeout
    while len(got) < n and time.monotonic() < deadline:
        msg = bus.recv(0.2)
        if msg is not None:
            got.append(msg)
    return got


@pytest.mark.parametrize("batched", [True, False], ids=["sendmmsg", "one-by-one"])
def test_staged_frames_reach_python_can_in_order(pair, batched):
    ours, theirs, _ = pair
    if not batched:
        ours._sendmmsg = None  # a libc without sendmmsg: one send per frame
    frames = [
        can.Message(arbitration_id=0x201 + k, data=bytes([k] * 8), is_extended_id=False)
        for k in range(8)
    ] + [can.Message(arbitration_id=0x80, data=b"\x05", is_extended_id=False)]
    for msg in frames:
        assert ours.stage(msg)
        msg.data[0:1] = b"\xff"  # packed when staged: changing the object later changes nothing
    assert list(received(theirs, 1, timeout=0.3)) == []  # nothing sent before the flush
    assert ours.flush() == len(frames)
    got = received(theirs, len(frames))
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [
        (0x201 + k, bytes([k] * 8)) for k in range(8)
    ] + [(0x80, b"\x05")]
    # never read back by our own socket (a CAN controller does not receive its own frames)
    assert ours.own_frames_dropped
    assert drained(ours, 1, timeout=0.3) == []
    assert ours.flush() == 0  # nothing staged


def test_only_our_own_flushed_frames_are_dropped():
    """Two cyclic buses on one group (the daemon's and the simulated robot's): each hears every
    frame the other flushes and none of its own; python-can's ``send`` (the set-up's path)
    still reaches both."""
    port = random.Random(os.getpid() * 31).randrange(40000, 50000)
    a = CyclicUdpMulticastBus(GROUP, port=port, fd=False)
    b = CyclicUdpMulticastBus(GROUP, port=port, fd=False)
    try:
        assert a.own_frames_dropped and b.own_frames_dropped
        for k in range(4):
            a.stage(can.Message(arbitration_id=0x201 + k, data=[k], is_extended_id=False))
            b.stage(can.Message(arbitration_id=0x181 + k, data=[k], is_extended_id=False))
        assert a.flush() == 4 and b.flush() == 4
        assert [f[0] for f in drained(b, 4)] == [0x201, 0x202, 0x203, 0x204]
        assert [f[0] for f in drained(a, 4)] == [0x181, 0x182, 0x183, 0x184]
        a.send(can.Message(arbitration_id=0x601, data=[1], is_extended_id=False), timeout=0)
        assert [f[0] for f in drained(b, 1)] == [0x601]
        time.sleep(0.05)  # loopback is delivered within the send: this is only margin
        assert list(a.drain_frames()) in ([], [(0x601, True, b"\x01")])  # python-can's echo
        assert list(b.drain_frames()) == []
    finally:
        a.shutdown()
        b.shutdown()


def test_the_medium_stays_on_this_machine_unless_told():
    """Hop limit 0 by default (a frame never goes out on the network card), python-can's
    ``hop_limit`` option still obeyed; both of the bus's sockets alike."""
    port = random.Random(os.getpid() * 37).randrange(40000, 50000)

    def ttls(bus: CyclicUdpMulticastBus) -> tuple[int, int]:
        def ttl(s: socket.socket) -> int:
            return s.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL)

        return ttl(bus._raw), ttl(bus._tx)

    local = CyclicUdpMulticastBus(GROUP, port=port, fd=False)
    lan = CyclicUdpMulticastBus(GROUP, port=port, fd=False, hop_limit=1)
    try:
        assert ttls(local) == (0, 0) and ttls(lan) == (1, 1)
        local.stage(can.Message(arbitration_id=0x181, data=[7], is_extended_id=False))
        local.flush()
        assert drained(lan, 1) == [(0x181, True, b"\x07")]  # still heard on this machine
    finally:
        local.shutdown()
        lan.shutdown()


def test_a_full_batch_refuses_more_and_stays_whole(pair):
    from drivers.udp_bus import MAX_STAGED

    ours, theirs, _ = pair
    msg = can.Message(arbitration_id=0x201, data=bytes(8), is_extended_id=False)
    assert all(ours.stage(msg) for _ in range(MAX_STAGED))
    assert not ours.stage(msg)
    assert ours.flush() == MAX_STAGED
    assert len(received(theirs, MAX_STAGED)) == MAX_STAGED


def test_the_driver_keeps_the_cycles_order_when_a_batch_fills(monkeypatch):
    """More frames in a cycle than a batch holds: what was staged goes first, so a SYNC never
    overtakes the RPDOs before it."""
    import drivers.udp_bus
    from cdprctl.robot_file import load_robot
    from drivers import create_driver

    monkeypatch.setattr(drivers.udp_bus, "MAX_STAGED", 3)
    port = random.Random(os.getpid() * 19).randrange(40000, 50000)
    model = load_robot(CONFIG / "rowc.toml")
    overrides = {"interface": "udp_multicast", "channel": GROUP, "options": {"port": port}}
    drv = create_driver(model, period=0.004, bus_overrides=overrides)
    peer = UdpMulticastBus(GROUP, port=port, fd=False)
    try:
        drv._open()
        assert drv.buses[0] is drv.buses[1]  # both buses on the one medium
        frames = [
            can.Message(arbitration_id=0x201 + k, data=bytes([k]), is_extended_id=False)
            for k in range(7)
        ]
        drv._batching = True
        for k, msg in enumerate(frames):
            assert drv._send(k % 2, msg)
        drv._batching = False
        drv._flush_staged()
        got = received(peer, len(frames))
        assert [m.arbitration_id for m in got] == [m.arbitration_id for m in frames]
        assert drv.stats.frames_sent == len(frames) and drv.stats.send_errors == 0
    finally:
        peer.shutdown()
        drv._close()


def test_a_channel_is_one_robot_groups_on_one_port_never_mix():
    """Two robots' buses on groups .97 and .98 of one port, and a python-can peer sending on
    .97: only .97's bus hears it, by the cycle's path and by python-can's ``recv`` (Linux
    delivers a socket bound to the port every joined group's datagrams unless
    IP_MULTICAST_ALL is off: ``drives scan`` on .98 found .97's eight drives)."""
    port = random.Random(os.getpid() * 29).randrange(40000, 50000)
    a = CyclicUdpMulticastBus("239.74.163.97", port=port, fd=False)
    b = CyclicUdpMulticastBus("239.74.163.98", port=port, fd=False)
    peer = UdpMulticastBus("239.74.163.97", port=port, fd=False)
    try:
        for k in range(3):
            peer.send(can.Message(arbitration_id=0x181 + k, data=[k], is_extended_id=False))
        assert [f[0] for f in drained(a, 3)] == [0x181, 0x182, 0x183]
        peer.send(can.Message(arbitration_id=0x701, data=[5], is_extended_id=False))
        assert a.recv(2.0).arbitration_id == 0x701
        time.sleep(0.05)  # loopback is delivered within the send: this is only margin
        assert list(b.drain_frames()) == [] and b.recv(0.0) is None
    finally:
        for bus in (a, b, peer):
            bus.shutdown()
