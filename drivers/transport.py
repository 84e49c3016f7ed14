"""The CAN transport every CAN protocol driver is composed with: the buses of the config (one
socket per medium), the node of each cable, sending (staged and sent together where the medium
can, with the traffic log and a failure streak) and receiving (the frames of our drives, by a
dispatch table the protocol fills). It knows nothing of a protocol; the driver
(``drivers/base.py``) opens and closes it and brackets each cycle's frames with
``begin_frames``/``end_frames``; the protocol sends by ``send`` and reads by ``receive``."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol

import can
import numpy as np

from cdprctl.core.numerics import add_count
from drivers.buses import TrafficLog, media_key, media_of, open_bus
from drivers.errors import DriverError, DriverOperationError
from drivers.vocabulary import FRAMES_IGNORED, FRAMES_RECEIVED, FRAMES_SENT, DriverStats

if TYPE_CHECKING:
    from cdprctl.model.drives import DrivesConfig


class Transport(Protocol):
    """What the driver itself asks of its medium (``drivers/base.py``); the protocol uses the
    rest of :class:`CanTransport` (sending, the frames received)."""

    batching: bool

    def open(self) -> None:
        """Open the buses (raise DriverInitializationError)."""

    def close(self) -> None:
        """Close the buses; idempotent."""

    def begin_frames(self, setup: bool) -> None:
        """A cycle's frames are about to be sent (``setup``: the set-up's, each of which waits
        for its answer, so none may be held back)."""

    def end_frames(self) -> None:
        """The cycle's frames were all given: send what was held back, in its order."""

    def flush_staged(self) -> None:
        """Send what is held back now."""

    def where(self, c: int) -> str:
        """Cable ``c``'s drive on the medium, for messages (" (node 3)")."""
        return ""


class CanTransport:
    """The python-can buses of one driver. ``buses``, ``media``, ``node`` and ``bus_of`` stay
    the same objects for its life (a driver shows them as its own; a test may wrap a bus in
    place)."""

    def __init__(self, m: int, config: DrivesConfig, overrides: dict[str, Any],
                 stats: DriverStats, clock: Callable[[], float]):  # fmt: skip
        """``m`` cables; ``config``: ``[drives]``; ``overrides``: the CLI's bus overrides;
        ``stats``: the driver's counters (frames sent, received, refused); ``clock``: s, for
        how long the bus has refused frames."""
        self.config = config
        self.overrides = overrides
        self.stats = stats
        self.clock = clock
        self.buses: list[can.BusABC] = []
        self.media: list[int] = []  # the bus of each distinct medium: broadcasts go there
        self._shared: dict[int, int] = {}  # bus → the first bus on its medium, when shared
        self.log: TrafficLog | None = None
        self.node = np.zeros(m, dtype=np.int64)  # CAN node id of each cable's drive
        self.bus_of = np.zeros(m, dtype=np.int64)  # bus index of each cable's drive
        for b, bus in enumerate(config.buses):
            for c, n in zip(bus.cables, bus.node_ids, strict=True):
                self.node[c], self.bus_of[c] = n, b
        # (bus, arbitration id) → (kind, cable): the frames the protocol reads (it fills it)
        self.dispatch: dict[tuple[int, int], tuple[int, int]] = {}
        self._send_fail_streak = 0  # frames refused in a row
        self._send_failing_since = math.inf  # clock s: when the bus began refusing them
        self.batching = False  # the cycle's frames are being staged (begin_frames)
        self._stage_of: list[Any] = []  # per bus: its medium's stage(msg), or None
        self._can_batch = False  # some medium stages (drivers/udp_bus.py)
        self._drain_of: list[Any] = []  # per bus: its medium's drain_frames, or None

    def open(self) -> None:
        """Open the buses (DriverInitializationError when one will not).

        One socket per medium: buses an override puts on one channel share the first one's
        (two sockets on one udp_multicast group received every frame twice: the read phase
        cost 614 µs median across processes at 250 Hz); the broadcasts go once per medium
        and the dispatch table is keyed by the medium's bus (drivers.buses.media_of)."""
        self.media[:] = media_of(self.config.buses, self.overrides)
        self._shared = {}
        first: dict[str, int] = {}
        for b, bus_cfg in enumerate(self.config.buses):
            key = media_key(bus_cfg, self.overrides, b)
            if key in first:
                self.buses.append(self.buses[first[key]])
                self._shared[b] = first[key]
            else:
                first[key] = b
                self.buses.append(open_bus(bus_cfg, self.overrides, b))
        if self._shared:
            self.dispatch = {
                (self._shared.get(b, b), arb): v for (b, arb), v in self.dispatch.items()
            }
        if self.config.log_file:
            self.log = TrafficLog(self.config.log_file)
        self._stage_of = [getattr(bus, "stage", None) for bus in self.buses]
        self._can_batch = any(s is not None for s in self._stage_of)
        self._drain_of = [getattr(bus, "drain_frames", None) for bus in self.buses]

    def close(self) -> None:
        """Close the buses; idempotent."""
        for b, bus in enumerate(self.buses):
            if b in self._shared:
                continue  # the medium's first bus closes it
            with contextlib.suppress(Exception):  # closing: nothing useful to do with it
                bus.shutdown()
        self.buses.clear()
        if self.log is not None:
            self.log.close()
            self.log = None

    def medium_of(self, b: int) -> int:
        """The bus whose medium bus ``b`` is on (itself unless it shares one)."""
        return self._shared.get(b, b)

    def where(self, c: int) -> str:
        """Cable ``c``'s drive on the bus, for messages."""
        return f" (node {int(self.node[c])})"

    def begin_frames(self, setup: bool) -> None:
        """A cycle's frames are about to be sent. On a medium that can batch them
        (``drivers/udp_bus.py``) they are staged and sent together at the end, in their order —
        one system call instead of one per frame, each of which woke the peers again. The
        set-up's frames (``setup``) go one by one: each waits for an answer."""
        self.batching = not setup and self._can_batch

    def end_frames(self) -> None:
        """The cycle's frames were all given: send what was staged, in its order."""
        if self.batching:
            self.batching = False
            self.flush_staged()

    def flush_staged(self) -> None:
        """Every medium's staged frames, sent; the refused ones counted."""
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

    def sends_failing(self) -> DriverError | None:
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

    def send(self, b: int, msg: can.Message) -> bool:
        """Send on bus ``b`` without blocking (staged while batching: counted at the flush); a
        failure is counted, never raised."""
        if self.batching:
            stage = self._stage_of[b]
            if stage is not None and not stage(msg):
                self.flush_staged()  # the batch is full: what came first goes first
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
        add_count(self.stats.counts, FRAMES_SENT, 1)
        if self.log is not None:
            self.log(msg)
        return True

    def receive(self, handler: Callable[[int, int, Any], None]) -> None:
        """Every frame waiting on every bus (``recv(0)``: never blocks) that belongs to one of
        our drives, handed to ``handler(kind, cable, data)`` by ``dispatch``; foreign,
        extended and remote frames are counted as ignored. By index, counted in place: no
        block of ours per cycle (a python-can bus's ``recv`` builds a Message per frame: the
        medium's; ``drain_frames``, a medium's own path, builds its tuples)."""
        dispatch, media, buses, counts = self.dispatch, self.media, self.buses, self.stats.counts
        received = ignored = 0
        i, n = 0, len(media)
        while i < n:
            b = media[i]
            i += 1
            drain = self._drain_of[b]
            if drain is not None and self.log is None:  # no Message per frame (udp_bus.py)
                for arb, plain, data in drain():
                    received += 1
                    key = dispatch.get((b, arb))
                    if key is None or not plain:
                        ignored += 1
                        continue
                    handler(key[0], key[1], data)
                continue
            bus = buses[b]
            while True:
                try:
                    msg = bus.recv(0)
                except can.CanError:  # the link down (ENETDOWN): nothing from this bus now;
                    self.stats.receive_errors += 1  # the feedback timeout judges how long
                    break
                if msg is None:
                    break
                received += 1
                if self.log is not None:
                    self.log(msg)
                key = dispatch.get((b, msg.arbitration_id))
                if key is None or msg.is_extended_id or msg.is_remote_frame:
                    ignored += 1
                    continue
                handler(key[0], key[1], msg.data)
        add_count(counts, FRAMES_RECEIVED, received)
        if ignored:
            add_count(counts, FRAMES_IGNORED, ignored)
