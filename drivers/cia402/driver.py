"""CiA 402 drives in cyclic synchronous torque or position mode over python-can buses.

Per cycle, ``read`` drains every bus with ``recv(0)`` and decodes TPDOs, EMCYs and heartbeats;
``write`` sends each drive's RPDO (controlword from the power-state table + target torque, or
in position mode target position + torque offset) and then SYNC on each bus, and the
controller's heartbeat when due. The SYNC carries its counter (0x1019): a drive that missed a
SYNC knows the target waiting for it was for the SYNC it missed. Set-up (NMT start, SDO: mode
of operation 10 or 8 by ``[drives] mode``, heartbeat producer time, abort-connection option
quick stop, SYNC counter, in position mode the following error) happens in ``configure``,
outside the loop.
"""

from __future__ import annotations

import math
from typing import Any

import can
import numpy as np

from cdprctl.numerics import kernel_args
from drivers import blocking
from drivers.base import WinchDriver
from drivers.cia402 import cyclic
from drivers.cia402 import protocol as p
from drivers.cia402.brake import command_brake
from drivers.cia402.capabilities import Capabilities, read_capabilities
from drivers.cia402.cyclic import GENERIC_STATE
from drivers.cia402.drive_setup import OPTIONAL, configure_drive
from drivers.cia402.sdo_client import SdoClient
from drivers.errors import (
    DriveFaultError,
    DriverError,
    DriverInitializationError,
    DriverOperationError,
    SafeTorqueOffError,
    following_error_text,
)
from drivers.registry import register_driver
from drivers.transport import CanTransport
from drivers.vocabulary import ACTIVE, ERROR, INACTIVE


@register_driver
class Cia402Driver(WinchDriver):
    name = "cia402"
    transport: CanTransport

    def __init__(self, model: Any, **kwargs: Any):
        super().__init__(model, **kwargs)
        cfg = self.config
        m = self.m
        self.transport = t = CanTransport(m, cfg, self.bus_overrides, self.stats,
                                          lambda: self.clock())  # fmt: skip
        self.buses, self.media, self.node, self.bus_of = t.buses, t.media, t.node, t.bus_of
        self._send = t.send  # an attribute: one call a frame (a test may wrap it)
        # (bus, arbitration id) → (kind, cable)
        for c in range(m):
            b, n = int(self.bus_of[c]), int(self.node[c])
            t.dispatch[(b, p.TPDO1 + n)] = (1, c)
            t.dispatch[(b, p.TPDO2 + n)] = (2, c)
            t.dispatch[(b, p.EMCY + n)] = (3, c)
            t.dispatch[(b, p.HEARTBEAT + n)] = (4, c)
            t.dispatch[(b, p.SDO_TX + n)] = (5, c)
        # each drive's mode (0x6060): [drives] mode, but torque mode for its torque_cables
        self.modes = [p.MODES[cfg.mode_of(c)] for c in range(m)]
        self._position = [mode == p.MODE_CSP for mode in self.modes]  # per drive
        self._csp = any(self._position)
        self._rpdo = [
            can.Message(arbitration_id=p.RPDO1 + int(self.node[c]), is_extended_id=False,
                        data=bytearray((p.RPDO1_CSP_STRUCT if self._position[c]
                                        else p.RPDO1_STRUCT).size))
            for c in range(m)
        ]  # fmt: skip
        # the RPDOs' bytes as arrays (views): cyclic.pack_rpdo1_kernel writes them in place
        self._rpdo_bytes = tuple(np.frombuffer(msg.data, dtype=np.uint8) for msg in self._rpdo)
        self._position_flags = np.array(self._position, dtype=bool)
        self._target_counts = np.zeros(m, dtype=np.int64)  # CSP: 0x607A of each drive
        self._last_targets = np.zeros(m)  # rad: the last cycle's targets, for their rate
        self._last_targets_t = -math.inf  # s: its time, -inf unless the drives ran (ACTIVE)
        self._carried = np.zeros(m)  # rad: the targets carried to the send (carry_targets)
        self._target_rate = np.zeros(m)  # rad/s: each target's rate since the last cycle's
        self.resent_targets = 0  # cycles whose targets went out again for a late SYNC
        # s: the most a cycle's targets are carried on to their send — as long as the feedback
        # they came from is trusted ([control] max_feedback_age; beyond it the supervisor
        # stops). Capped at 20 ms, holds of 20-40 ms still reversed the drives and faulted
        # (rowc, lock-step, random holds; with the cap at 50 ms they stayed within 0.09 rad)
        self.max_carry = model.control.max_feedback_age
        # CSP: 0x6065 of each drive (counts), at least one count
        self._following_window = np.array(
            [
                max(1, min(p.FOLLOWING_ERROR_OFF - 1, round(
                    cfg.following_error_window_rad(c.winch) / (2.0 * math.pi) * self.encoder_cpr[i]
                )))
                for i, c in enumerate(model.cables)
            ],
            dtype=np.int64,
        )  # fmt: skip
        # 0x6072 of each drive: its winch's torque limit, per mille of the rated torque
        self._max_torque_pm = np.array(
            [min(0xFFFF, round(c.winch.torque_limit / cfg.rated_torque * 1000.0))
             for c in model.cables],
            dtype=np.int64,
        )  # fmt: skip
        self.identities: list[dict[str, int] | None] = [None] * m  # 0x1018, read at set-up
        self._dcf = [""] * m  # each drive's DCF ([[drives.buses]] dcf)
        for bus in cfg.buses:
            for k, cable in enumerate(bus.cables):
                self._dcf[cable] = bus.dcf_of(k)
        self.pdos_written = 0  # PDOs the set-up had to write (0: all were as needed)
        # per drive: reset (power-up, reset node or communication) since cdprctl last set it
        # up, seen at set-up: its producer heartbeat time 0x1017 is back at its default (the
        # EDS's 0), never cdprctl's value. An incremental encoder's counter restarted with it
        # (docs/homing.md)
        self._reset_flags = [False] * m
        self.reset_since_setup = self._reset_flags
        self._sync = can.Message(arbitration_id=p.SYNC, data=bytearray(1), is_extended_id=False)
        self._sync_plain = can.Message(arbitration_id=p.SYNC, data=b"", is_extended_id=False)
        # per bus: its medium's SYNC carries the counter (every drive there has 0x1019)
        self._sync_counted = [True] * len(cfg.buses)
        # per drive: the optional objects its set-up skipped, and why (drive_setup.OPTIONAL)
        self.skipped: list[list[str]] = [[] for _ in range(m)]
        self._hb = can.Message(
            arbitration_id=p.HEARTBEAT + cfg.controller_node_id,
            data=bytes([p.HB_OPERATIONAL]),
            is_extended_id=False,
        )
        self.rated_torque = cfg.rated_torque  # N·m per 1000 per-mille
        self.rad_per_count = 2.0 * math.pi / self.encoder_cpr
        # raw feedback
        self._ps = np.full(m, int(p.PowerState.NOT_READY_TO_SWITCH_ON), dtype=np.int64)
        self._counts = np.zeros(m, dtype=np.int64)  # unwrapped multi-turn counts
        # per cable: last 32-bit position (for unwrapping), 1 once there is one, implausible
        # frames in a row
        self._raw = np.zeros((m, 3), dtype=np.int64)
        self.liveness.implausible = self._raw[:, 2]  # a view: what the liveness error reports
        self._prev = np.full((m, 2), -math.inf)  # last position (rad) and its instant (s)
        self._tpdo1 = np.zeros((4 * m, 4), dtype=np.int64)  # the cycle's TPDO1s, decoded
        # ... and as received: their bytes (copied in, decoded by a kernel) and their cables
        self._tpdo1_bytes = bytearray(8 * 4 * m)
        self._tpdo1_raw = np.frombuffer(self._tpdo1_bytes, dtype=np.uint8).reshape(4 * m, 8)
        self._tpdo1_cable = np.zeros(4 * m, dtype=np.int64)
        self._rpdo_fields = np.zeros((m, 2), dtype=np.int64)  # controlword, torque per-mille
        self._generic = np.array([int(GENERIC_STATE[s]) for s in sorted(p.PowerState)])
        st = self.states
        self._decoded = kernel_args(
            cyclic.Decoded(self._raw, self._counts, self._ps, np.zeros(m, dtype=np.int64),
                           self._prev)
        )  # fmt: skip
        self._emcy = self._decoded[3]
        self._feedback = (st.position, st.velocity, st.state, st.fault_code)
        self._nmt_state = np.full(m, -1, dtype=np.int64)
        self._sdo_reply: dict[int, bytes] = {}
        self.sdo = SdoClient(self)
        self._enable = False
        self._reset_request = 0  # cycles left sending the fault-reset edge
        self._last_sync = math.nan  # s (clock): the last SYNC sent (nan: none yet)
        # the SYNCs' instants by sequence number (a ring), the newest's number, and the one
        # each drive's last TPDO1 answered: each frame is stamped at its own SYNC's instant
        self._syncs = np.full(self.SYNC_RING, math.nan)
        self._sync_seq = 0
        self._answered = np.zeros(m, dtype=np.int64)
        self._rate = np.zeros(m)  # counts/s: each drive's last step over its time
        self._write_sync = math.nan  # s (clock): the last write's SYNC (nan: it sent none)
        self._last_cycle_sync = -math.inf  # s (clock): the last one the control loop sent
        self._last_hb_sent = -math.inf
        self._bus_of_list = [int(b) for b in self.bus_of]

    # -- hooks: set-up ------------------------------------------------------------------------
    def _configure_drives(self, timeout: float) -> None:
        """Each drive in PRE-OPERATIONAL by SDO (``drive_setup.configure_drive``), then NMT
        start."""
        self.sdo.nmt_all(p.NMT_PRE_OPERATIONAL)  # one left operational (a restart) too
        caps = [self._capabilities(c, timeout) for c in range(self.m)]
        refused = [(c, why) for c, cap in enumerate(caps) if (why := cap.can_run(self.modes[c]))]
        if refused:  # before any drive is written to: every mapping as it was
            raise DriverInitializationError(
                "; ".join(f"drive of cable index {c} (node {int(self.node[c])}) cannot run "
                          f"cdprctl: {why}" for c, why in refused)
                + " (nothing was written to any drive; `cdprctl drives scan` lists them all)"
            )  # fmt: skip
        # a SYNC with a counter byte on a medium where a drive has no 0x1019 would be one of
        # the wrong length to it (CiA 301 §7.2.5: EMCY 0x8240 on a real drive)
        counter = self._sync_counted
        for c, cap in enumerate(caps):
            if not cap.present[p.OD_SYNC_COUNTER_OVERFLOW]:
                counter[self._medium_of(c)] = False
        for c in range(self.m):
            configure_drive(self, self.sdo, c, timeout, caps[c], counter[self._medium_of(c)])
        self.sdo.nmt_all(p.NMT_START)
        self.liveness.started = True

        # cycle (zero torque, drives disabled) until every drive has sent feedback
        def resend_start(now: float) -> None:
            if int(now / 0.5) != int((now - self.period) / 0.5):
                self.sdo.nmt_all(p.NMT_START)  # a lost NMT start (lossy buses) is sent again

        blocking.await_first_feedback(
            self,
            timeout,
            lambda: bool(np.all(np.isfinite(self.liveness.fb_stamp))),
            "feedback (TPDO1)",
            resend_start,
        )

    def _capabilities(self, c: int, timeout: float) -> Capabilities:
        return read_capabilities(
            lambda index, sub: self.sdo.read(c, index, sub, timeout, signed=False),
            tuple(OPTIONAL),
        )

    def command_brake(self, c: int, closed: bool, timeout: float) -> None:
        if self.lifecycle not in (INACTIVE, ERROR):  # SDO: not cyclic
            raise DriverOperationError(f"brake command while {self.lifecycle.name}: disabled only")
        command_brake(self.sdo, c, closed, timeout)

    def _medium_of(self, c: int) -> int:
        return self.transport.medium_of(int(self.bus_of[c]))

    def _request_enable(self, enable: bool) -> None:
        self._enable = enable

    def _fault_reset(self) -> None:
        self._reset_request = 4  # a few cycles of 0x00 then 0x80: a clean rising edge

    # -- hooks: the cyclic path ---------------------------------------------------------------
    def _warm_up(self) -> None:
        super()._warm_up()
        m = self.m
        self._apply_tpdo1(0, 0.0)  # no frame: nothing written
        cyclic.state_kernel(
            np.zeros(m, dtype=bool), self.liveness.fb_stamp, self.rad_per_count, True,
            self._generic, tuple(a.copy() for a in self._decoded),
            tuple(a.copy() for a in self._feedback),
        )  # fmt: skip
        cyclic.controlword_kernel(
            np.zeros(m),
            self._ps,
            self._emcy.copy(),
            0,
            False,
            self.rated_torque,
            cyclic.CONTROLWORD_TOWARDS_ENABLED,
            self._rpdo_fields.copy(),
        )
        cyclic.target_rates_kernel(
            self.targets, 0.0, self._last_targets.copy(), -1.0, self.liveness.max_motor_speed,
            self._target_rate.copy(),
        )  # fmt: skip
        cyclic.carry_targets_kernel(self.targets, self._target_rate, 0.0, self._carried.copy())
        cyclic.target_counts_kernel(self.targets, self.rad_per_count, self._target_counts.copy())
        cyclic.pack_rpdo1_kernel(
            self._rpdo_fields, self._target_counts, self._position_flags,
            tuple(b.copy() for b in self._rpdo_bytes),
        )  # fmt: skip

    SYNC_RING = 8  # SYNC instants kept
    SYNC_LAG_MAX = 4  # SYNCs a late TPDO1 may answer behind the newest (``sync_instant``)
    # of a period: targets this much older than their SYNC are sent again (``_write_frames``)
    RESEND_AFTER = 0.25
    # times the targets may go out again before one SYNC (each check costs a clock read)
    RESEND_TRIES = 3

    def _sent_instant(self) -> float:
        """The write's SYNC, when it sent one: the drives take their targets at it, sample
        their feedback for it (the TPDOs are stamped with it), and the simulated robot of
        ``cdprctl run --sim`` handles the frames there (``sent_at``). Stamped after the
        write returned instead, the VM holding the process up past the SYNC put the
        simulated SYNC that much after the instant its targets were carried to: a reversal
        the next late SYNC doubled, a following-error fault at 500 Hz on the spring robot
        (seed000 and seed000_grippers in position mode, real time: 6 runs of 35; since, 1 of
        16 — not the whole cause, docs/control.md "Known limits")."""
        s = self._write_sync
        return s if math.isfinite(s) else self.clock()

    def _send_targets(self, late: float, fields: np.ndarray) -> None:
        """Position mode: each drive's RPDO (controlword, the target carried ``late`` s on at
        its rate, the torque offset); a drive in torque mode among them (a gripper's) gets
        its controlword and torque."""
        cyclic.carry_targets_kernel(self.targets, self._target_rate, late, self._carried)
        cyclic.target_counts_kernel(self._carried, self.rad_per_count, self._target_counts)
        self._send_rpdos(fields)

    def _send_rpdos(self, fields: np.ndarray) -> None:
        """Each drive's RPDO1, packed by a kernel (no list, no int per value), then sent."""
        cyclic.pack_rpdo1_kernel(fields, self._target_counts, self._position_flags,
                                 self._rpdo_bytes)  # fmt: skip
        send, bus_of, rpdo = self._send, self._bus_of_list, self._rpdo
        for c in range(self.m):
            send(bus_of[c], rpdo[c])

    def _drain(self, t: float) -> None:
        """Decode every frame waiting on every bus (``recv(0)``: never blocks); the TPDO1s are
        applied together, in their order of arrival (``cyclic.tpdo1_synced_kernel``)."""
        tp2, raw, cables, n = p.TPDO2_STRUCT.unpack, self._tpdo1_bytes, self._tpdo1_cable, 0
        pdo_velocity = self.config.velocity_source == "pdo"
        for kind, c, data in self.transport.frames():
            if kind == 1 and len(data) == 8:
                if n == len(cables):  # more than 4 per drive since the last read: apply them
                    self._apply_tpdo1(n, t)
                    n = 0
                cables[n] = c
                raw[8 * n : 8 * n + 8] = data  # unpacked, its fields were an int each
                n += 1
            elif kind == 2 and len(data) == 4:
                if pdo_velocity:
                    self.states.velocity[c] = tp2(data)[0] * self.rad_per_count[c]
            elif kind == 3 and len(data) == 8:
                self._emcy[c] = p.EMCY_STRUCT.unpack(data)[0]
            elif kind == 4 and len(data) >= 1:
                self.liveness.last_hb[c] = t
                self._nmt_state[c] = data[0]
            elif kind == 5 and len(data) == 8:
                self._sdo_reply[c] = bytes(data)
            else:
                self.stats.frames_ignored += 1
        if n:
            self._apply_tpdo1(n, t)

    def _apply_tpdo1(self, n: int, t: float) -> None:
        cyclic.decode_tpdo1_kernel(n, self._tpdo1_raw, self._tpdo1_cable, self._tpdo1)
        dropped = cyclic.tpdo1_synced_kernel(
            n, self._tpdo1, self._syncs, self._sync_seq, self._answered, self.SYNC_LAG_MAX, t,
            self.period, self.liveness.max_motor_speed, self.rad_per_count, self.rated_torque,
            cyclic.POWER_STATE_OF_SW7, self._decoded, self.states.torque, self.liveness.fresh,
            self.liveness.fb_stamp, self._rate,
        )  # fmt: skip
        self.stats.implausible_frames += dropped

    def _update_states(self) -> bool:
        lv = self.liveness
        return bool(
            cyclic.state_kernel(
                lv.fresh, lv.fb_stamp, self.rad_per_count,
                self.config.velocity_source == "derived", self._generic, self._decoded,
                self._feedback,
            )
        )  # fmt: skip

    def _cable_fault(self, c: int) -> DriverError | None:
        code = int(self._emcy[c])
        if code != 0 or self._ps[c] == p.PowerState.FAULT:
            kind = SafeTorqueOffError if code in p.STO_CODES else DriveFaultError
            text = p.describe_emcy(code) if code else "fault (statusword)"
            if code == p.EMCY_FOLLOWING_ERROR:  # how far, by the last target and feedback
                w = self.model.cables[c].winch
                text = following_error_text(
                    abs(float(self.targets[c] - self.states.position[c])),
                    self._following_window[c] * 2.0 * math.pi / self.encoder_cpr[c],
                    w.drum_radius / w.gear_ratio, self.config.following_error_timeout,
                    "the drive's 0x6065/0x6066; the distance is cdprctl's, from its last "
                    "target and feedback")  # fmt: skip
            return kind(c, int(self.node[c]), code, text)
        return None

    def _write_frames(self, t: float, torques: np.ndarray, setup: bool) -> DriverError | None:
        reset = self._reset_request
        if reset:
            self._reset_request -= 1
        self._write_sync = math.nan  # s (clock): this write's SYNC, when it sends one
        fields = self._rpdo_fields
        cyclic.controlword_kernel(
            torques,
            self._ps,
            self._emcy,
            reset,
            self._enable,
            self.rated_torque,
            cyclic.CONTROLWORD_TOWARDS_ENABLED,
            fields,
        )
        if self._csp:
            # A cycle held up between its start and this send (the VM taking the CPU for
            # 4-10 ms mid-cycle, across processes) sent targets for an instant long past with
            # a SYNC of now: the drives, which had gone on at the targets' rate, reversed and
            # faulted on their following error. The targets go out for the SYNC's instant.
            # Only between two cycles of running drives: the step at an enable is no rate.
            late = min(max(self.clock() - t, 0.0), self.max_carry) if not setup else 0.0
            running = self.lifecycle is ACTIVE
            since = self._last_targets_t if running else -math.inf
            cyclic.target_rates_kernel(
                self.targets, t, self._last_targets, since, self.liveness.max_motor_speed,
                self._target_rate,
            )  # fmt: skip
            self._last_targets_t = t if running else -math.inf
            self._send_targets(late, fields)
        else:
            self._send_rpdos(fields)
        # The SYNC is the drives' time base: the control loop never sends two within half a
        # period (on the clock: a late cycle's time is not when it sends). A late cycle
        # followed at once by the next one (a loaded machine) sent SYNCs 0 ms apart, then
        # none for 16 ms: the drives' interpolation overshot and faulted on its following
        # error (across processes, 2 busy loops on 2 cores). Its RPDOs wait for the next.
        now = self.clock()
        if setup or now - self._last_cycle_sync >= 0.5 * self.period:
            if self._csp and not setup:
                # held up within its sends (the VM taking the CPU between the RPDOs and the
                # SYNC, 5 ms under a CPU hog with --sim), the targets went out for an instant
                # well before their SYNC: the drives saw them behind, reversed, and over the
                # next late SYNCs overshot into a following-error fault. Sent again for now,
                # and checked again: held up once more while they went out again, they were
                # that much behind (rowc, two 10 ms holds: 0.37 rad, a fault; lock-step)
                for _ in range(self.RESEND_TRIES):
                    again = min(max(now - t, 0.0), self.max_carry)
                    if again - late <= self.RESEND_AFTER * self.period:
                        break
                    self._send_targets(again, fields)
                    self.resent_targets += 1
                    late, now = again, self.clock()
            sync = self._sync.data
            sync[0] = sync[0] % p.SYNC_COUNTER_OVERFLOW + 1
            for b in self.media:
                self._send(b, self._sync if self._sync_counted[b] else self._sync_plain)
            self._last_sync = self._write_sync = now
            self._sync_seq += 1
            self._syncs[self._sync_seq % self.SYNC_RING] = now
            if not setup:
                self._last_cycle_sync = now
        if t - self._last_hb_sent >= self.config.heartbeat_period:
            for b in self.media:
                self._send(b, self._hb)
            self._last_hb_sent = t
        return self.transport.sends_failing()
