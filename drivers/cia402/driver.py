"""CiA 402 drives in cyclic synchronous torque or position mode over python-can buses.

Per cycle, ``read`` drains every bus with ``recv(0)`` and decodes TPDOs, EMCYs and heartbeats
(``feedback.Cia402Feedback``); ``write`` sends each drive's RPDO (controlword from the
power-state table + target torque, or in position mode target position + torque offset) and
then SYNC on each bus (its timing: ``sync_clock.SyncClock``), and the controller's heartbeat
when due. The SYNC carries its counter (0x1019): a drive that missed a SYNC knows the target
waiting for it was for the SYNC it missed. Set-up (NMT start, SDO: mode of operation 10 or 8 by
``[drives] mode``, heartbeat producer time, abort-connection option quick stop, SYNC counter,
in position mode the following error) happens in ``configure``, outside the loop
(``drive_setup``, through the SDO client's port).

The driver is composed: a transport (``drivers/transport.CanTransport``), the read side, the
SYNC clock and the SDO client, each its own object; this class is the one hook layer of
``drivers/base.py`` and the write path.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import can
import numpy as np

from cdprctl.core.numerics import max2, min2
from drivers import blocking
from drivers.base import WinchDriver
from drivers.cia402 import cyclic, drive_setup
from drivers.cia402 import protocol as p
from drivers.cia402.brake import command_brake
from drivers.cia402.capabilities import Capabilities, read_capabilities
from drivers.cia402.drive_setup import OPTIONAL, DriveRecord, configure_drive
from drivers.cia402.feedback import SDO, Cia402Feedback
from drivers.cia402.sdo_client import DriverSdoPort, SdoClient
from drivers.cia402.sync_clock import SyncClock
from drivers.errors import (
    DriveFaultError,
    DriverError,
    DriverInitializationError,
    DriverOperationError,
    SafeTorqueOffError,
    following_error_text,
)
from drivers.load_cells import LoadCells
from drivers.registry import register_driver
from drivers.transport import CanTransport
from drivers.vocabulary import ACTIVE, ERROR, INACTIVE


@register_driver
class Cia402Driver(WinchDriver):
    name = "cia402"
    transport: CanTransport
    # of a period: targets this much older than their SYNC are sent again (``SyncClock``)
    RESEND_AFTER = SyncClock.RESEND_AFTER
    # times the targets may go out again before one SYNC (each check costs a clock read)
    RESEND_TRIES = SyncClock.RESEND_TRIES

    def __init__(self, model: Any, **kwargs: Any):
        super().__init__(model, **kwargs)
        cfg, m = self.config, self.m
        self.transport = t = CanTransport(m, cfg, self.bus_overrides, self.stats,
                                          lambda: self.clock())  # fmt: skip
        self.buses, self.media, self.node, self.bus_of = t.buses, t.media, t.node, t.bus_of
        self._send = t.send  # an attribute: one call a frame (a test may wrap it)
        # each drive's mode (0x6060): [drives] mode, but torque mode for its torque_cables
        self.modes = [p.MODES[cfg.mode_of(c)] for c in range(m)]
        self.plans = drive_setup.plans(cfg, model.cables, self.node, self.modes, self.encoder_cpr)
        # CSP: 0x6065 of each drive (counts), at least one count
        self._following_window = np.array([pl.following_window for pl in self.plans])
        self.rated_torque = cfg.rated_torque  # N·m per 1000 per-mille
        self.rad_per_count = 2.0 * math.pi / self.encoder_cpr
        self.sync = SyncClock(m, self.period, len(cfg.buses))
        self.feedback = Cia402Feedback(
            m, self.period, self.rad_per_count, self.rated_torque, cfg.velocity_source, t,
            self.sync, self.states, self.liveness, self.stats,
        )  # fmt: skip
        self.feedback.dispatch_into(t.dispatch, self.node, self.bus_of)
        self.sdo = SdoClient(DriverSdoPort(
            self.bus_of, self.node, t.media, self.feedback.sdo_reply, self.period, t.send,
            self.feedback.drain, self.clock, self.wait,
        ))  # fmt: skip
        # the load cells on these buses: their TPDOs, and an SDO port numbering them after
        # the drives (drivers/load_cells.py)
        self.cells = LoadCells(model.sensors.load_cells, m, self.states)
        self.cells.dispatch_into(t.dispatch, m, SDO)
        self.feedback.on_cell = self.cells.receive
        port = self.sdo.port
        assert isinstance(port, DriverSdoPort)
        self.cells_sdo = SdoClient(dataclasses.replace(
            port, bus_of=np.concatenate([self.bus_of, self.cells.bus]),
            node=np.concatenate([self.node, self.cells.node]),
        ))  # fmt: skip
        # what the set-up found: each drive's 0x1018; the optional objects its set-up skipped
        # and why (drive_setup.OPTIONAL); the PDOs it had to write (0: all were as needed);
        # per drive, reset (power-up, reset node or communication) since cdprctl last set it
        # up: its producer heartbeat time 0x1017 back at its default (the EDS's 0), never
        # cdprctl's value. An incremental encoder's counter restarted with it (docs/homing.md)
        self.identities: list[dict[str, int] | None] = [None] * m
        self.skipped: list[list[str]] = [[] for _ in range(m)]
        self.pdos_written = 0
        self._reset_flags = [False] * m
        self.reset_since_setup = self._reset_flags
        self._init_write_path(model)

    def _init_write_path(self, model: Any) -> None:
        """The RPDOs (one message each, packed in place), the position targets' carry, the
        controller's heartbeat and the enable and fault-reset requests."""
        m = self.m
        position = [mode == p.MODE_CSP for mode in self.modes]  # per drive
        self._csp = any(position)
        self._rpdo = [
            can.Message(arbitration_id=p.RPDO1 + int(self.node[c]), is_extended_id=False,
                        data=bytearray((p.RPDO1_CSP_STRUCT if position[c]
                                        else p.RPDO1_STRUCT).size))
            for c in range(m)
        ]  # fmt: skip
        # the RPDOs' bytes as arrays (views): cyclic.pack_rpdo1_kernel writes them in place
        self._rpdo_bytes = tuple(np.frombuffer(msg.data, dtype=np.uint8) for msg in self._rpdo)
        self._position_flags = np.array(position, dtype=bool)
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
        self._rpdo_fields = np.zeros((m, 2), dtype=np.int64)  # controlword, torque per-mille
        self._hb = can.Message(
            arbitration_id=p.HEARTBEAT + self.config.controller_node_id,
            data=bytes([p.HB_OPERATIONAL]),
            is_extended_id=False,
        )
        self._last_hb_sent = -math.inf
        self._bus_of_list = [int(b) for b in self.bus_of]
        self._enable = False
        self._reset_request = 0  # cycles left sending the fault-reset edge

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
        counter = self.sync.counted
        for c, cap in enumerate(caps):
            if not cap.present[p.OD_SYNC_COUNTER_OVERFLOW]:
                counter[self._medium_of(c)] = False
        for c in range(self.m):
            self._configure_drive(c, timeout, caps[c], counter[self._medium_of(c)])
        self.cells.configure(self.cells_sdo, self.config.pdo_mapping == "configure", timeout)
        self.sdo.nmt_all(p.NMT_START)
        self.liveness.started = True

        # cycle (zero torque, drives disabled) until every drive has sent feedback
        def resend_start(now: float) -> None:
            if int(now / 0.5) != int((now - self.period) / 0.5):
                self.sdo.nmt_all(p.NMT_START)  # a lost NMT start (lossy buses) is sent again

        blocking.await_first_feedback(
            self,
            timeout,
            lambda: bool(np.all(np.isfinite(self.liveness.fb_stamp))) and self.cells.all_heard(),
            "feedback (TPDO1, and the load cells' TPDOs)",
            resend_start,
        )

    def _configure_drive(self, c: int, timeout: float, caps: Capabilities, counter: bool) -> None:
        """The set-up of drive ``c`` by its plan; what it found kept (also when it fails)."""
        record = DriveRecord(skipped=self.skipped[c])
        try:
            configure_drive(self.sdo, self.plans[c], record, timeout, caps, counter)
        finally:
            self.identities[c] = record.identity
            if record.reset is not None:
                self._reset_flags[c] = record.reset
            self.pdos_written += record.pdos_written

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
        self.feedback.warm_up()
        if self.cells.cells:
            self.cells.warm_up()
        cyclic.controlword_kernel(
            np.zeros(m),
            self.feedback.ps,
            self.feedback.emcy.copy(),
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

    def _sent_instant(self) -> float:
        """The write's SYNC, when it sent one: the drives take their targets at it, sample
        their feedback for it (the TPDOs are stamped with it), and the simulated robot of
        ``cdprctl run --sim`` handles the frames there (``sent_at``). Stamped after the
        write returned instead, the VM holding the process up past the SYNC put the
        simulated SYNC that much after the instant its targets were carried to: a reversal
        the next late SYNC doubled, a following-error fault at 500 Hz on the spring robot
        (seed000 and seed000_grippers in position mode, real time: 6 runs of 35; since, 1 of
        16 — not the whole cause, docs/control.md "Known limits")."""
        s = self.sync.of_write
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
        c, m = 0, self.m
        while c < m:  # by index: a for loop's iterator was a block
            send(bus_of[c], rpdo[c])
            c += 1

    def _drain(self, t: float) -> None:
        self.feedback.drain(t)
        if self.cells.cells:
            self.cells.update(t)

    def _update_states(self) -> bool:
        return self.feedback.update_states()

    def _cable_fault(self, c: int) -> DriverError | None:
        if not self.feedback.in_fault(c):
            return None
        code = int(self.feedback.emcy[c])
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

    def _write_frames(self, t: float, torques: np.ndarray, setup: bool) -> DriverError | None:
        reset = self._reset_request
        if reset:
            self._reset_request -= 1
        self.sync.begin_write()
        fields = self._rpdo_fields
        cyclic.controlword_kernel(
            torques,
            self.feedback.ps,
            self.feedback.emcy,
            reset,
            self._enable,
            self.rated_torque,
            cyclic.CONTROLWORD_TOWARDS_ENABLED,
            fields,
        )
        late = 0.0
        if self._csp:
            # A cycle held up between its start and this send (the VM taking the CPU for
            # 4-10 ms mid-cycle, across processes) sent targets for an instant long past with
            # a SYNC of now: the drives, which had gone on at the targets' rate, reversed and
            # faulted on their following error. The targets go out for the SYNC's instant.
            # Only between two cycles of running drives: the step at an enable is no rate.
            late = min2(max2(self.clock() - t, 0.0), self.max_carry) if not setup else 0.0
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
        now = self.clock()
        if self.sync.due(now, setup):  # else its RPDOs wait for the next SYNC
            self._send_sync(t, now, late, fields, setup)
        if t - self._last_hb_sent >= self.config.heartbeat_period:
            media, i = self.media, 0
            while i < len(media):
                self._send(media[i], self._hb)
                i += 1
            self._last_hb_sent = t
        return self.transport.sends_failing()

    def _send_sync(self, t: float, now: float, late: float, fields: np.ndarray,
                   setup: bool) -> None:  # fmt: skip
        """The SYNC on every medium, the cycle's targets sent again first if they went out
        too long before it."""
        sync = self.sync
        if self._csp and not setup:
            # held up within its sends (the VM taking the CPU between the RPDOs and the
            # SYNC, 5 ms under a CPU hog with --sim), the targets went out for an instant
            # well before their SYNC: the drives saw them behind, reversed, and over the
            # next late SYNCs overshot into a following-error fault. Sent again for now,
            # and checked again: held up once more while they went out again, they were
            # that much behind (rowc, two 10 ms holds: 0.37 rad, a fault; lock-step)
            tries = 0
            while tries < self.RESEND_TRIES:
                tries += 1
                again = min2(max2(now - t, 0.0), self.max_carry)
                if not sync.behind(late, again, self.RESEND_AFTER):
                    break
                self._send_targets(again, fields)
                self.resent_targets += 1
                late, now = again, self.clock()
        sync.advance()
        frame, plain, counted, media = sync.frame, sync.plain, sync.counted, self.media
        i, n = 0, len(media)
        while i < n:
            b = media[i]
            self._send(b, frame if counted[b] else plain)
            i += 1
        sync.sent(now, setup)
