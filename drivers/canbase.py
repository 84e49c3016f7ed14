"""The CAN transport every CAN protocol driver shares: the buses of the config (one socket per
medium), the node of each cable, sending (staged and sent together where the medium can, with
the traffic log and a failure streak) and receiving (the frames of our drives, by a dispatch
table). It implements the base's transport hooks (``_open``, ``_close``, ``_begin_frames``,
``_end_frames``); the protocol implements the rest (``drivers/base.py``)."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from typing import Any

import can
import numpy as np

from drivers.base import WinchDriver
from drivers.buses import TrafficLog, media_key, media_of, open_bus
from drivers.errors import DriverError, DriverOperationError


class CanWinchDriver(WinchDriver):
    """A :class:`WinchDriver` on python-can buses; protocols subclass it."""

    def __init__(self, model: Any, **kwargs: Any):
        super().__init__(model, **kwargs)
        self.buses: list[can.BusABC] = []
        self.media: list[int] = []  # the bus of each distinct medium: broadcasts go there
        self._shared: dict[int, int] = {}  # bus → the first bus on its medium, when shared
        self.log: TrafficLog | None = None
        self.node = np.zeros(self.m, dtype=np.int64)  # CAN node id of each cable's drive
        self.bus_of = np.zeros(self.m, dtype=np.int64)  # bus index of each cable's drive
        for b, bus in enumerate(self.config.buses):
            for c, n in zip(bus.cables, bus.node_ids, strict=True):
                self.node[c], self.bus_of[c] = n, b
        self._send_fail_streak = 0  # frames refused in a row
        self._send_failing_since = math.inf  # clock s: when the bus began refusing them
        self._batching = False  # the cycle's frames are being staged (_begin_frames)
        self._stage_of: list[Any] = []  # per bus: its medium's stage(msg), or None
        self._can_batch = False  # some medium stages (drivers/udp_bus.py)
        self._drain_of: list[Any] = []  # per bus: its medium's drain_frames, or None
        self._dispatch: dict[tuple[int, int], tuple[int, int]] = {}  # filled by protocols

    def _open(self) -> None:
        # One socket per medium: buses an override puts on one channel share the first one's
        # (two sockets on one udp_multicast group received every frame twice: the read phase
        # cost 614 µs median across processes at 250 Hz); the broadcasts go once per medium
        # and the dispatch table is keyed by the medium's bus (drivers.buses.media_of).
        self.media = media_of(self.config.buses, self.bus_overrides)
        self._shared = {}
        first: dict[str, int] = {}
        for b, bus_cfg in enumerate(self.config.buses):
            key = media_key(bus_cfg, self.bus_overrides, b)
            if key in first:
                self.buses.append(self.buses[first[key]])
                self._shared[b] = first[key]
            else:
                first[key] = b
                self.buses.append(open_bus(bus_cfg, self.bus_overrides, b))
        if self._shared:
            self._dispatch = {
                (self._shared.get(b, b), arb): v for (b, arb), v in self._dispatch.items()
            }
        if self.config.log_file:
            self.log = TrafficLog(self.config.log_file)
        self._stage_of = [getattr(bus, "stage", None) for bus in self.buses]
        self._can_batch = any(s is not None for s in self._stage_of)
        self._drain_of = [getattr(bus, "drain_frames", None) for bus in self.buses]

    def _close(self) -> None:
        for b, bus in enumerate(self.buses):
            if b in self._shared:
                continue  # the medium's first bus closes it
            with contextlib.suppress(Exception):  # closing: nothing useful to do with it
                bus.shutdown()
        self.buses = []
        if self.log is not None:
            self.log.close()
            self.log = None

    def _begin_frames(self, setup: bool) -> None:
        """On a medium that can batch them (``drivers/udp_bus.py``) the cycle's frames are
        staged and sent together at the end, in their order — one system call instead of one
        per frame, each of which woke the peers again. The set-up's frames go one by one: each
        waits for an answer."""
        self._batching = not setup and self._can_batch

    def _end_frames(self) -> None:
        if self._batching:
            self._batching = False
            self._flush_staged()

    def _flush_staged(self) -> None:
        for b in self.media:
            if self._stage_of[b] is None:
                continue
            bus: Any = self.buses[b]  # one with stage/flush (udp_bus.CyclicUdpMulticastBus)
            n = bus.staged
            if n == 0:
                continue
            sent = bus.flush()
            self.stats.frames_sent += sent
            if sent < n:
                self.stats.send_errors += n - sent
                self._refused(n - sent)
            else:
                self._send_fail_streak = 0

    def _refused(self, n: int) -> None:
        """``n`` frames the bus would not take, in a row with those before."""
        if self._send_fail_streak == 0:
            self._send_failing_since = self.clock()
        self._send_fail_streak += n

    def _sends_failing(self) -> DriverError | None:
        """An error once the bus has refused every frame for longer than the feedback may be
        missing (``[drives] feedback_timeout``): the drives have gone that long without our
        targets. Shorter (a TX queue full for a moment, a link down for a blink): ridden
        through, counted in ``stats.send_errors``; the drives' own comm timeout guards them."""
        if self._send_fail_streak == 0:
            return None
        refusing = self.clock() - self._send_failing_since
        if refusing <= self.config.feedback_timeout:
            return None
        return DriverOperationError(
            f"the CAN bus refused every frame for {refusing:.3f} s ({self._send_fail_streak} in "
            f"a row: link down, bus-off or TX queue full; longer than [drives] feedback_timeout "
            f"{self.config.feedback_timeout:g} s)"
        )

    def _send(self, b: int, msg: can.Message) -> bool:
        """Send on bus ``b`` without blocking (staged while batching: counted at the flush); a
        failure is counted, never raised."""
        if self._batching:
            stage = self._stage_of[b]
            if stage is not None and not stage(msg):
                self._flush_staged()  # the batch is full: what came first goes first
                if not stage(msg):  # still no room: the frame goes alone, after them
                    stage = None
            if stage is not None:
                if self.log is not None:
                    self.log(msg)
                return True
        try:
            self.buses[b].send(msg, timeout=0)
        except can.CanError:
            self.stats.send_errors += 1
            self._refused(1)
            return False
        self._send_fail_streak = 0
        self.stats.frames_sent += 1
        if self.log is not None:
            self.log(msg)
        return True

    def _frames(self) -> Iterator[tuple[int, int, bytearray]]:
        """Every frame waiting on every bus (``recv(0)``: never blocks) that belongs to one of
        our drives: ``(kind, cable, data)`` from the subclass's ``_dispatch`` table of
        ``(bus, arbitration id) → (kind, cable)``; foreign, extended and remote frames are
        counted as ignored."""
        dispatch = self._dispatch
        for b in self.media:
            bus = self.buses[b]
            drain = self._drain_of[b]
            if drain is not None and self.log is None:  # no Message per frame (udp_bus.py)
                for arb, plain, data in drain():
                    self.stats.frames_received += 1
                    key = dispatch.get((b, arb))
                    if key is None or not plain:
                        self.stats.frames_ignored += 1
                        continue
                    yield key[0], key[1], data
                continue
            while True:
                try:
                    msg = bus.recv(0)
                except can.CanError:  # the link down (ENETDOWN): nothing from this bus now;
                    self.stats.receive_errors += 1  # the feedback timeout judges how long
                    break
                if msg is None:
                    break
                self.stats.frames_received += 1
                if self.log is not None:
                    self.log(msg)
                key = dispatch.get((b, msg.arbitration_id))
                if key is None or msg.is_extended_id or msg.is_remote_frame:
                    self.stats.frames_ignored += 1
                    continue
                yield key[0], key[1], msg.data

    def _where(self, c: int) -> str:
        return f"{self.drive_label} of cable index {c} (node {int(self.node[c])})"
