"""The CiA 402 driver's read side: every frame of its drives decoded into the driver's state —
TPDO1s (statusword, torque, position; applied together by a kernel, each stamped at the SYNC
it answers), TPDO2s (velocity), EMCYs, heartbeats (NMT state) and SDO answers — then the
winches' states and faults from it, once a cycle (``cyclic.state_kernel``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cdprctl.core.numerics import add_count, kernel_args
from drivers.cia402 import cyclic
from drivers.cia402 import protocol as p
from drivers.cia402.cyclic import GENERIC_STATE
from drivers.cia402.sync_clock import SyncClock
from drivers.liveness import Liveness
from drivers.vocabulary import IMPLAUSIBLE_FRAMES, DriverStats, WinchStates

# frame kinds of the dispatch table (``Cia402Feedback.dispatch_into``)
TPDO1, TPDO2, EMCY, HEARTBEAT, SDO = 1, 2, 3, 4, 5


class Cia402Feedback:
    """The decoding state of ``m`` drives (arrays, written in place) and the read's steps."""

    def __init__(self, m: int, period: float, rad_per_count: np.ndarray, rated_torque: float,
                 velocity_source: str, transport: Any, sync: SyncClock, states: WinchStates,
                 liveness: Liveness, stats: DriverStats):  # fmt: skip
        """``rad_per_count`` per drive, ``rated_torque`` (N·m per 1000 per-mille),
        ``velocity_source`` ([drives]: "pdo" or "derived"); the frames come from
        ``transport.receive``, the SYNCs' instants from ``sync``; the decoded feedback goes
        into ``states`` and ``liveness`` (and the dropped frames into ``stats``)."""
        self.m, self.period = m, period
        self.rad_per_count, self.rated_torque = rad_per_count, rated_torque
        self.pdo_velocity = velocity_source == "pdo"
        self.derived = velocity_source == "derived"
        self.transport, self.sync = transport, sync
        self.states, self.liveness, self.stats = states, liveness, stats
        self.ps = np.full(m, int(p.PowerState.NOT_READY_TO_SWITCH_ON), dtype=np.int64)
        self.counts = np.zeros(m, dtype=np.int64)  # unwrapped multi-turn counts
        # per cable: last 32-bit position (for unwrapping), 1 once there is one, implausible
        # frames in a row
        self.raw = np.zeros((m, 3), dtype=np.int64)
        liveness.implausible = self.raw[:, 2]  # a view: what the liveness error reports
        self.prev = np.full((m, 2), -math.inf)  # last position (rad) and its instant (s)
        self.tpdo1 = np.zeros((4 * m, 4), dtype=np.int64)  # the cycle's TPDO1s, decoded
        # ... and as received: their bytes (copied in, decoded by a kernel) and their cables
        self.tpdo1_bytes = bytearray(8 * 4 * m)
        self.tpdo1_raw = np.frombuffer(self.tpdo1_bytes, dtype=np.uint8).reshape(4 * m, 8)
        self.tpdo1_cable = np.zeros(4 * m, dtype=np.int64)
        self._slots = 4 * m  # TPDO1s the arrays hold
        self._n = 0  # TPDO1s received in this read
        self._t = 0.0  # s, this read's time
        self._on_frame = self._frame  # bound once: a bound method per read was a block
        self.generic = np.array([int(GENERIC_STATE[s]) for s in sorted(p.PowerState)])
        self.decoded = kernel_args(
            cyclic.Decoded(self.raw, self.counts, self.ps, np.zeros(m, dtype=np.int64),
                           self.prev)
        )  # fmt: skip
        self.emcy = self.decoded[3]  # the last EMCY code of each drive (0: none)
        self.feedback = (states.position, states.velocity, states.state, states.fault_code)
        self.nmt_state = np.full(m, -1, dtype=np.int64)  # from each drive's heartbeat
        self.sdo_reply: dict[int, bytes] = {}  # cable → its drive's last SDO answer
        # a load cell's TPDO (kind 6, drivers/load_cells.py): (cell, data) → kept
        self.on_cell: Any = None

    def dispatch_into(self, dispatch: dict[tuple[int, int], tuple[int, int]],
                      node: np.ndarray, bus_of: np.ndarray) -> None:  # fmt: skip
        """The frames of each drive (``node`` on bus ``bus_of``) into the transport's
        ``dispatch`` table: (bus, arbitration id) → (kind, cable)."""
        for c in range(self.m):
            b, n = int(bus_of[c]), int(node[c])
            dispatch[(b, p.TPDO1 + n)] = (TPDO1, c)
            dispatch[(b, p.TPDO2 + n)] = (TPDO2, c)
            dispatch[(b, p.EMCY + n)] = (EMCY, c)
            dispatch[(b, p.HEARTBEAT + n)] = (HEARTBEAT, c)
            dispatch[(b, p.SDO_TX + n)] = (SDO, c)

    def drain(self, t: float) -> None:
        """Decode every frame waiting on every bus (``recv(0)``: never blocks); the TPDO1s are
        applied together, in their order of arrival (``cyclic.tpdo1_synced_kernel``)."""
        self._t, self._n = t, 0
        self.transport.receive(self._on_frame)
        if self._n:
            self.apply_tpdo1(self._n, t)

    def _frame(self, kind: int, c: int, data: Any) -> None:
        """One frame of drive ``c`` (the kinds as literals: no lookup)."""
        if kind == 1 and len(data) == 8:
            n = self._n
            if n == self._slots:  # more than 4 per drive since the last read: apply them
                self.apply_tpdo1(n, self._t)
                n = 0
            self.tpdo1_cable[n] = c
            self.tpdo1_bytes[8 * n : 8 * n + 8] = data  # unpacked, its fields were an int each
            self._n = n + 1
        elif kind == 2 and len(data) == 4:
            if self.pdo_velocity:
                self.states.velocity[c] = p.TPDO2_STRUCT.unpack(data)[0] * self.rad_per_count[c]
        elif kind == 3 and len(data) == 8:
            self.emcy[c] = p.EMCY_STRUCT.unpack(data)[0]
        elif kind == 4 and len(data) >= 1:
            self.liveness.last_hb[c] = self._t
            self.nmt_state[c] = data[0]
        elif kind == 5 and len(data) == 8:
            self.sdo_reply[c] = bytes(data)
        elif kind == 6 and self.on_cell is not None:  # a load cell's TPDO (drivers/load_cells.py)
            self.on_cell(c, data)
        else:
            self.stats.frames_ignored += 1

    def apply_tpdo1(self, n: int, t: float) -> None:
        """The ``n`` TPDO1s received, decoded and applied (``t``: s, before the first SYNC)."""
        cyclic.decode_tpdo1_kernel(n, self.tpdo1_raw, self.tpdo1_cable, self.tpdo1)
        sync, lv = self.sync, self.liveness
        dropped = cyclic.tpdo1_synced_kernel(
            n, self.tpdo1, sync.instants, sync.seqs, sync.answered, sync.LAG_MAX, t,
            self.period, lv.max_motor_speed, self.rad_per_count, self.rated_torque,
            cyclic.POWER_STATE_OF_SW7, self.decoded, self.states.torque, lv.fresh,
            lv.fb_stamp, sync.rate,
        )  # fmt: skip
        if dropped:
            add_count(self.stats.counts, IMPLAUSIBLE_FRAMES, dropped)

    def update_states(self) -> bool:
        """The winches' states from the decoded feedback; True if a drive is in fault."""
        lv = self.liveness
        return bool(
            cyclic.state_kernel(lv.fresh, lv.fb_stamp, self.rad_per_count, self.derived,
                                self.generic, self.decoded, self.feedback)
        )  # fmt: skip

    def in_fault(self, c: int) -> bool:
        """Drive ``c`` reports a fault: an EMCY code, or the FAULT power state."""
        return int(self.emcy[c]) != 0 or self.ps[c] == p.PowerState.FAULT

    def warm_up(self) -> None:
        """The read's kernels once (no frame: nothing written; the states on copies)."""
        self.apply_tpdo1(0, 0.0)
        cyclic.state_kernel(
            np.zeros(self.m, dtype=bool), self.liveness.fb_stamp, self.rad_per_count, True,
            self.generic, tuple(a.copy() for a in self.decoded),
            tuple(a.copy() for a in self.feedback),
        )  # fmt: skip
