"""Benchmark: what the udp_multicast medium itself costs a control cycle on this machine — the
floor under the daemon's read and write phases across processes, without any of its code.

Each round sleeps one period first (the loop's caches are as cold), then times:
- write: the cycle's 9 frames (rowc on one medium: 8 RPDOs and a SYNC) by python-can's
  ``send`` (one ``sendto`` each), by bare ``sendto`` (the kernel alone) and staged and flushed
  in one ``sendmmsg`` (the driver's path, drivers/udp_bus.py);
- read: 20 waiting frames (8 TPDOs, our own 9 echoed back, heartbeats) by python-can's
  ``recv(0)`` and by the cyclic bus's ``drain_frames`` (drivers/udp_bus.py), per frame.
A second process reads the group like ``cdprctl sim`` does (blocked in python-can's ``recv``),
so every send wakes a peer as in the real run.

Run: ``.venv/bin/python benchmarks/bench_udp_medium.py [--rounds 400] [--period 0.002]``.
"""

from __future__ import annotations

import argparse
import os
import random
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import numpy as np
from can.interfaces.udp_multicast.utils import pack_message

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from _timing import machine_line

from drivers.udp_bus import CyclicUdpMulticastBus

GROUP = "239.74.163.2"
FRAMES_OUT = 9
FRAMES_IN = 20

PEER = """
import sys, can
bus = can.Bus(interface="udp_multicast", channel=sys.argv[1], port=int(sys.argv[2]))
print("up", flush=True)
while True:
    bus.recv(1.0)
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=400)
    ap.add_argument("--period", type=float, default=0.002, help="s slept before each round")
    args = ap.parse_args()
    print(machine_line())
    port = random.Random(os.getpid()).randrange(40000, 50000)
    ours = CyclicUdpMulticastBus(GROUP, port=port, fd=False)
    other = CyclicUdpMulticastBus(GROUP, port=port, fd=False)  # fills our queue for the reads
    peer = subprocess.Popen([sys.executable, "-c", PEER, GROUP, str(port)], stdout=subprocess.PIPE)
    times: dict[str, list[float]] = {k: [] for k in ("send", "sendto", "sendmmsg", "recv", "drain")}
    try:
        assert peer.stdout is not None
        peer.stdout.readline()
        raw = socket.socket(fileno=os.dup(ours.fileno()))
        for _ in range(args.rounds):
            one_round(ours, other, raw, (GROUP, port), args.period, times)
        raw.close()
    finally:
        peer.kill()
        peer.wait()
        ours.shutdown()
        other.shutdown()
    print_results(times, args.rounds, args.period)


def one_round(ours, other, raw: socket.socket, dest: tuple[str, int], period: float,
              times: dict[str, list[float]]) -> None:  # fmt: skip
    """One round of each way to write (s per cycle's frames) and to read (s per frame), each
    after a period asleep with both queues drained; appended to ``times``."""
    msg = can.Message(arbitration_id=0x201, data=bytearray(8), is_extended_id=False)
    datagram = pack_message(msg)

    def settle() -> None:
        time.sleep(period)
        list(ours.drain_frames())
        list(other.drain_frames())
        time.sleep(period)

    settle()
    t0 = time.perf_counter()
    for _ in range(FRAMES_OUT):
        ours.send(msg, timeout=0)
    times["send"].append(time.perf_counter() - t0)
    settle()
    t0 = time.perf_counter()
    for _ in range(FRAMES_OUT):
        raw.sendto(datagram, dest)
    times["sendto"].append(time.perf_counter() - t0)
    settle()
    t0 = time.perf_counter()
    for _ in range(FRAMES_OUT):
        ours.stage(msg)
    ours.flush()
    times["sendmmsg"].append(time.perf_counter() - t0)
    for how in ("recv", "drain"):
        settle()
        for _ in range(FRAMES_IN):
            other.send(msg, timeout=0)
        list(other.drain_frames())
        time.sleep(period)
        t0 = time.perf_counter()
        if how == "recv":
            n = 0
            while ours.recv(0) is not None:
                n += 1
        else:
            n = sum(1 for _ in ours.drain_frames())
        if n:
            times[how].append((time.perf_counter() - t0) / n)


def print_results(times: dict[str, list[float]], rounds: int, period: float) -> None:
    """Median and p99 (µs) of each way, and the medium's floor of a rowc cycle."""

    def line(name: str, xs: list[float], what: str) -> None:
        if xs:
            a = np.asarray(xs) * 1e6
            p50, p99 = np.median(a), np.percentile(a, 99)
            print(f"  {name:34s} median {p50:6.1f} us  p99 {p99:6.1f} us  ({what})")

    print(f"{rounds} rounds, each after {period * 1e3:g} ms asleep, a peer process reading:")
    line(f"write {FRAMES_OUT} frames, python-can send", times["send"], "one sendto each")
    line(f"write {FRAMES_OUT} frames, bare sendto", times["sendto"], "the kernel alone")
    line(f"write {FRAMES_OUT} frames, stage + flush", times["sendmmsg"], "the driver's path")
    line("read a frame, python-can recv(0)", times["recv"], "per frame")
    line("read a frame, drain_frames", times["drain"], "per frame, the driver's path")
    if times["drain"]:
        floor = np.median(times["sendmmsg"]) + FRAMES_IN * np.median(times["drain"])
        print(f"the medium's floor of a rowc cycle (9 sent, 20 read): {floor * 1e6:.0f} us")


if __name__ == "__main__":
    main()
