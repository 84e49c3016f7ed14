"""What every CAN protocol driver shares: the buses of the config, the node of each cable,
sending (with the traffic log and a failure streak), and the liveness rules (feedback age,
missed cycles, heartbeat)."""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from typing import Any

import can
import numpy as np
from numba import njit

from cdprctl.numerics import plausible_step_py
from drivers.base import WinchDriver
from drivers.buses import TrafficLog, media_key, media_of, open_bus
from drivers.errors import DriverError, DriverTimeoutError


class CanWinchDriver(WinchDriver):
    """A :class:`WinchDriver` on python-can buses; protocols subclass it."""

    #: what the drive is called in messages, and what its cyclic feedback is
    drive_label = "drive"
    feedback_label = "feedback"

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
        self._send_fail_streak = 0
        self._batching = False  # the cycle's frames are being staged (_write_internal)
        self._stage_of: list[Any] = []  # per bus: its medium's stage(msg), or None
        self._can_batch = False  # some medium stages (drivers/udp_bus.py)
        self._drain_of: list[Any] = []  # per bus: its medium's drain_frames, or None
        self._dispatch: dict[tuple[int, int], tuple[int, int]] = {}  # filled by protocols
        # liveness bookkeeping, per cable
        self._fresh = np.zeros(self.m, dtype=bool)  # feedback arrived during this read
        self._fb_stamp = np.full(self.m, -math.inf)  # s, time of the last feedback
        self._missed = np.zeros(self.m, dtype=np.int64)  # consecutive reads without feedback
        # s of running cycles without feedback, per cable: each read adds the time since the
        # last one, at most two periods — a stall of the loop itself sends no SYNC, so the
        # drives could not answer; it is the loop's to report, not a drive's silence
        self._silent = np.zeros(self.m)
        self._last_hb = np.full(self.m, -math.inf)  # s, the drive's last heartbeat
        self._last_read = -math.inf
        self._started = False  # the drives were started: silence now counts
        # Plausibility of position feedback: a step no motor can make between two samples is a
        # corrupted frame (or a failing encoder) and is dropped like a lost one; the liveness
        # check then stops the robot if it persists.
        r = np.array([w.winch.drum_radius / w.winch.gear_ratio for w in model.cables])
        self._max_motor_speed = self.PLAUSIBLE_CABLE_SPEED / r  # rad/s
        self._implausible = np.zeros(self.m, dtype=np.int64)  # in a row, per cable

    PLAUSIBLE_CABLE_SPEED = 5.0  # m/s of cable: five times the supervisor's speed limit

    def _plausible(self, c: int, step: float, stamp: float) -> bool:
        """Whether motor ``c`` can have turned by ``step`` (rad) since its last accepted
        sample, at ``stamp`` (s); counts the implausible ones."""
        prev = self._fb_stamp[c]
        if not math.isfinite(prev):
            return True
        # a period of slack for timing jitter (the one rule: cdprctl.numerics.plausible_step)
        if plausible_step_py(step, float(self._max_motor_speed[c]), stamp - prev, self.period):
            self._implausible[c] = 0
            return True
        self._implausible[c] += 1
        self.stats.implausible_frames += 1
        return False

    def _await_first_feedback(
        self, timeout: float, heard: Any, what: str, on_tick: Any = None
    ) -> None:
        """Cycle (zero torque, drives disabled) until ``heard()`` says every drive has sent
        feedback; ``on_tick(now)`` once a cycle (a repeated NMT start, say). Raises
        ``DriverTimeoutError`` naming the silent cables' indices and ``what`` was awaited."""
        deadline = self.clock() + timeout
        while True:
            now = self.clock()
            self._read_internal(now)
            self._write_internal(now, np.zeros(self.m), setup=True)
            if heard():
                return
            if on_tick is not None:
                on_tick(now)
            if now > deadline:
                silent = [c for c in range(self.m) if not np.isfinite(self._fb_stamp[c])]
                raise DriverTimeoutError(
                    f"no {what} from the drives of cable indices {silent} within {timeout:g} s",
                    silent[0] if silent else None,
                )
            self.wait(self.period)

    def _warm_up(self) -> None:
        super()._warm_up()
        liveness_kernel(
            self._fresh.copy(),
            self._fb_stamp.copy(),
            self._missed.copy(),
            self._silent.copy(),
            self._last_hb.copy(),
            0.0,
            0.002,
            True,
            self.config.feedback_timeout,
            self.config.heartbeat_timeout,
            self.states.feedback_age.copy(),
            self.states.sampled_at.copy(),
        )

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

    def _write_internal(
        self, t: float, torques: np.ndarray, setup: bool = False
    ) -> DriverError | None:
        """The cycle's frames (``_write_frames``); on a medium that can batch them
        (``drivers/udp_bus.py``) staged and sent together at the end, in their order — one
        system call instead of one per frame, each of which woke the peers again. The set-up's
        frames go one by one: each waits for an answer."""
        self._batching = not setup and self._can_batch
        err = self._write_frames(t, torques, setup)
        if self._batching:
            self._batching = False
            self._flush_staged()
        return err

    def _write_frames(
        self, t: float, torques: np.ndarray, setup: bool = False
    ) -> DriverError | None:
        """Send the cycle's frames with ``_send``; an error when sending keeps failing."""
        raise NotImplementedError

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
                self._send_fail_streak += n - sent
            else:
                self._send_fail_streak = 0

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
            self._send_fail_streak += 1
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
                msg = bus.recv(0)
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

    def _read_internal(self, t: float) -> DriverError | None:
        """Drain the feedback, then every cable's state and liveness (compiled, once per
        cycle); when one is wrong, the first error in cable order, a cable's drive fault
        before its timeout (``_cable_fault``, ``_liveness_error``)."""
        self._fresh[:] = False
        self._drain(t)
        gap = self._read_gap(t)
        fault = self._update_states()
        missed, late = liveness_kernel(
            self._fresh,
            self._fb_stamp,
            self._missed,
            self._silent,
            self._last_hb,
            t,
            gap,
            self._started,
            self.config.feedback_timeout,
            self.config.heartbeat_timeout,
            self.states.feedback_age,
            self.states.sampled_at,
        )
        self.stats.missed_feedback += missed
        if not (fault or late):
            return None
        for c in range(self.m):
            err = self._cable_fault(c) or self._liveness_error(c, t)
            if err is not None:
                return err
        return None

    def _drain(self, t: float) -> None:
        """Decode every waiting frame (``_frames``) into the protocol's state."""
        raise NotImplementedError

    def _update_states(self) -> bool:
        """``self.states`` of every cable from the decoded feedback; True if a drive reports a
        fault. The default asks ``_cable_fault`` cable by cable."""
        return any([self._cable_fault(c) is not None for c in range(self.m)])

    def _cable_fault(self, c: int) -> DriverError | None:
        """Cable ``c``'s drive fault, if any (sets its state and fault code)."""
        raise NotImplementedError

    def _read_gap(self, t: float) -> float:
        """s since the last read, at most two periods (0 at the same instant: that misses
        nothing; the first read: one period)."""
        gap = t - self._last_read if math.isfinite(self._last_read) else self.period
        self._last_read = t
        return min(max(gap, 0.0), 2.0 * self.period)

    def _where(self, c: int) -> str:
        return f"{self.drive_label} of cable index {c} (node {int(self.node[c])})"

    def _liveness_error(self, c: int, t: float) -> DriverError | None:
        """The timeout error of cable ``c`` when a limit is passed (``feedback_timeout`` s
        without feedback, ``heartbeat_timeout`` s without heartbeat)."""
        age = float(self.states.feedback_age[c])
        if self._silent[c] > self.config.feedback_timeout:
            why = (
                f" (the last {int(self._implausible[c])} were position jumps no motor can "
                "make: corrupted frames or a failing encoder)"
                if self._implausible[c]
                else ""
            )
            return DriverTimeoutError(
                f"{self._where(c)}: no {self.feedback_label} for {self._silent[c] * 1e3:.1f} ms "
                f"of running cycles ({int(self._missed[c])} reads, last {age * 1e3:.1f} ms ago; "
                f"feedback_timeout {self.config.feedback_timeout * 1e3:g} ms){why}",
                c,
            )
        if (
            self._started
            and math.isfinite(self._last_hb[c])
            and t - self._last_hb[c] > self.config.heartbeat_timeout
        ):
            return DriverTimeoutError(
                f"{self._where(c)} lost: no heartbeat for {t - self._last_hb[c]:.3f} s "
                f"(timeout {self.config.heartbeat_timeout:g} s)",
                c,
            )
        return None


@njit(cache=True)
def liveness_kernel(
    fresh, fb_stamp, missed, silent, last_hb, t, gap, started, fb_timeout, hb_timeout, age,
    sampled,
):  # pragma: no cover - compiled  # fmt: skip
    """Per cable: the count of consecutive reads without feedback and their time ``silent``
    (s; each read adds ``gap``, the capped time since the last read; silence counts once the
    drives were started and have spoken), the feedback age (s) and instant (``sampled``, s).
    Returns the cable-reads missed now and whether a cable was silent over ``fb_timeout`` s or
    ``hb_timeout`` s without heartbeat."""
    n_missed = 0
    late = False
    for c in range(len(fresh)):
        if fresh[c]:
            missed[c] = 0
            silent[c] = 0.0
        elif gap > 0.0 and started and np.isfinite(fb_stamp[c]):
            missed[c] += 1
            silent[c] += gap
            n_missed += 1
        age[c] = t - fb_stamp[c]
        sampled[c] = fb_stamp[c]
        if silent[c] > fb_timeout:
            late = True
        if started and np.isfinite(last_hb[c]) and t - last_hb[c] > hb_timeout:
            late = True
    return n_missed, late
