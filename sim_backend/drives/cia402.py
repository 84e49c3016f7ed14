"""A CiA 402 drive as the simulator's CAN node: it answers the frames a real drive answers.

NMT (pre-operational → operational on "start"), SDO server (expedited) for the objects the
driver configures, RPDO1 latched and applied at the next SYNC (CiA 301 synchronous PDO) in
cyclic synchronous torque (mode 10) or position (mode 8: the target interpolated linearly
between SYNCs, the drive's own position loop run at every physics step, ``physics.Servo``), TPDO1
(and TPDO2) sampled at the SYNC, the power state machine of CiA 402 (the transition table of
``drivers.cia402.protocol``), heartbeat production (0x1017), EMCY on faults, and drive-side
safety: the communication timeout triggers the abort-connection option (0x6007: quick stop),
the following error in position mode (beyond 0x6065 for longer than 0x6066: FAULT, EMCY
0x8611), the torque limit, and the brake that holds the drum whenever the drive is not
enabled.
"""

from __future__ import annotations

import math

import can

from drivers.cia402 import protocol as p
from sim_backend.physics import following_error_py
from sim_backend.plant import CdprPlant


class Cia402Drive:
    def __init__(
        self,
        node_id: int,
        cable: int,
        plant: CdprPlant,
        rated_torque: float,
        counts_per_rev: int,
        torque_limit: float,
        comm_timeout: float,
        velocity_pdo: bool = False,
        position_gains: tuple[float, float] = (0.0, 0.0),
    ):
        self.node_id = node_id
        self.velocity_pdo = velocity_pdo  # TPDO2 (0x606C) mapped and sent on SYNC
        self.cable = cable
        self.plant = plant
        self.rated_torque = rated_torque  # N·m per 1000 per-mille
        self.cpr = counts_per_rev
        self.torque_limit = torque_limit
        self.comm_timeout = comm_timeout
        # the position loop's gains in mode 8 (N·m/rad, N·m·s/rad): the drive's own tuning
        self.position_gains = position_gains
        self.last_sync = -math.inf
        self.sync_count = 0  # the last SYNC's counter (0: none, or SYNCs without one)
        self.rpdos_since_sync = 0  # RPDOs received since the last SYNC this drive saw
        self.stale_targets = 0  # RPDOs not taken: they were for a SYNC this drive missed
        self.last_target = -math.inf  # s, the SYNC that applied the last RPDO
        self.sync_period = 0.0  # s, the drive's estimate (0: none yet)
        self._intervals: list[float] = []  # s, the last SYNC intervals
        self.nmt = p.HB_PRE_OPERATIONAL
        self.state = p.PowerState.SWITCH_ON_DISABLED  # transitions 0 and 1 done at power-on
        self.od: dict[tuple[int, int], int] = {
            (p.OD_MODES_OF_OPERATION, 0): 0,
            (p.OD_MODES_DISPLAY, 0): 0,
            (p.OD_PRODUCER_HEARTBEAT, 0): 0,
            (p.OD_ABORT_CONNECTION, 0): 1,
            (p.OD_RATED_TORQUE, 0): round(rated_torque * 1000),
            # not monitored until configured (the controller writes both in position mode)
            (p.OD_FOLLOWING_ERROR_WINDOW, 0): p.FOLLOWING_ERROR_OFF,
            (p.OD_FOLLOWING_ERROR_TIMEOUT, 0): 10,
            (p.OD_SYNC_COUNTER_OVERFLOW, 0): 0,  # SYNC without a counter until configured
        }
        # (controlword, target torque or position, torque offset per-mille)
        self.pending: tuple[int, int, int] | None = None
        self.torque_pm = 0  # applied: the target torque (mode 10), the offset (mode 8)
        self.target_counts: int | None = None  # mode 8: the last target position
        self.last_controlword = 0
        self.last_rx = -math.inf  # last RPDO or SYNC
        self.last_hb = -math.inf
        self.fault_code = 0
        self.silent = False  # fault injection: the drive stops talking
        self.encoder_offset = 0  # counts, fault injection: an encoder jump
        self.transitions: list[int] = []  # CiA 402 transition numbers taken (for tests)
        self._set_following_error()

    # -- frames in ------------------------------------------------------------------------------
    def on_nmt(self, command: int) -> None:
        if command == p.NMT_START:
            self.nmt = p.HB_OPERATIONAL
        elif command == p.NMT_STOP:
            self.nmt = p.HB_STOPPED
        elif command == p.NMT_PRE_OPERATIONAL:
            self.nmt = p.HB_PRE_OPERATIONAL
        elif command in (p.NMT_RESET_NODE, p.NMT_RESET_COMMUNICATION):
            self.nmt = p.HB_PRE_OPERATIONAL
            self.state = p.PowerState.SWITCH_ON_DISABLED
            self.pending = None

    @property
    def mode(self) -> int:
        return self.od[(p.OD_MODES_OF_OPERATION, 0)]

    def on_rpdo(self, data: bytes, t: float) -> None:
        if self.nmt != p.HB_OPERATIONAL:
            return
        if self.mode == p.MODE_CSP and len(data) == 8:
            self.pending = p.RPDO1_CSP_STRUCT.unpack(data)
        elif self.mode != p.MODE_CSP and len(data) == 4:
            self.pending = (*p.RPDO1_STRUCT.unpack(data), 0)
        else:  # not this mode's mapping: ignored, like a real drive's length check
            return
        self.rpdos_since_sync += 1
        self.last_rx = t

    def on_sdo(self, data: bytes) -> can.Message | None:
        if len(data) != 8 or self.silent:
            return None
        cmd, index, sub, raw = p.SDO_STRUCT.unpack(data)
        key = (index, sub)
        if cmd & 0xE0 == 0x20:  # download (expedited)
            size = 4 - ((cmd >> 2) & 0x3) if cmd & 0x1 else 4
            value = int.from_bytes(raw[:size], "little", signed=index in self.SIGNED_OBJECTS)
            if key not in self.od or key == (p.OD_MODES_DISPLAY, 0):
                return self._sdo_abort(index, sub, 0x06020000 if key not in self.od else 0x06010002)
            if key == (p.OD_MODES_OF_OPERATION, 0) and value not in (p.MODE_CSP, p.MODE_CST):
                return self._sdo_abort(index, sub, 0x06090030)  # value range exceeded
            self.od[key] = value
            if key == (p.OD_MODES_OF_OPERATION, 0):
                self.od[(p.OD_MODES_DISPLAY, 0)] = value
            if index in (p.OD_FOLLOWING_ERROR_WINDOW, p.OD_FOLLOWING_ERROR_TIMEOUT):
                self._set_following_error()
            return self._sdo_answer(p.SDO_STRUCT.pack(0x60, index, sub, b"\0\0\0\0"))
        if cmd & 0xE0 == 0x40:  # upload
            if key not in self.od:
                return self._sdo_abort(index, sub, 0x06020000)
            value = self.od[key]
            return self._sdo_answer(
                p.SDO_STRUCT.pack(0x43, index, sub, (value & 0xFFFFFFFF).to_bytes(4, "little"))
            )
        return self._sdo_abort(index, sub, 0x05040001)

    # INTEGER objects (CiA 402: the modes, the abort-connection option); every other one here
    # is UNSIGNED (0x1017 := 40,000 ms stored signed read back −25,536)
    SIGNED_OBJECTS = frozenset({p.OD_MODES_OF_OPERATION, p.OD_MODES_DISPLAY, p.OD_ABORT_CONNECTION})

    def _set_following_error(self) -> None:
        """The position loop's following-error window (rad) and time-out (s) from 0x6065 and
        0x6066: set when they are written, not at every SYNC."""
        window = self.od[(p.OD_FOLLOWING_ERROR_WINDOW, 0)] & 0xFFFFFFFF
        servo, c = self.plant.servo, self.cable
        off = window == p.FOLLOWING_ERROR_OFF
        servo.window[c] = math.inf if off else window * 2.0 * math.pi / self.cpr
        servo.timeout[c] = self.od[(p.OD_FOLLOWING_ERROR_TIMEOUT, 0)] / 1000.0

    def _sdo_answer(self, data: bytes) -> can.Message:
        return can.Message(arbitration_id=p.SDO_TX + self.node_id, data=data, is_extended_id=False)

    def _sdo_abort(self, index: int, sub: int, code: int) -> can.Message:
        return self._sdo_answer(p.SDO_STRUCT.pack(0x80, index, sub, code.to_bytes(4, "little")))

    def on_sync(self, t: float, data: bytes = b"") -> list[can.Message]:
        """Apply the latched RPDO, then sample and send the TPDOs."""
        self.last_rx = t
        interval, self.last_sync = t - self.last_sync, t
        self._measure_sync_period(interval)
        stale = self._missed_sync_since_rpdo(data)
        if self.nmt != p.HB_OPERATIONAL:
            return []
        pending, self.pending = self.pending, None
        if pending is not None and stale:
            pending = None  # not taken: as across a lost RPDO, the target goes on
            self.stale_targets += 1
        if pending is not None:
            self.last_target = t
            cw, value, offset = pending
            self._apply_controlword(cw)
            if self.mode == p.MODE_CSP:
                self.target_counts, self.torque_pm = value, offset
            else:
                self.torque_pm = value
        self._apply_to_plant(interval, pending is not None)
        if self.silent:
            return []
        counts = self._counts()
        if self.state is not p.PowerState.OPERATION_ENABLED:
            applied_pm = 0
        elif self.mode == p.MODE_CSP:  # what the position loop applies now
            applied_pm = round(self.plant.servo.applied[self.cable] * 1000.0 / self.rated_torque)
            applied_pm = max(-32767, min(32767, applied_pm))
        else:
            applied_pm = self.torque_pm
        sw = p.STATUSWORD_OF[self.state]
        out = [
            can.Message(
                arbitration_id=p.TPDO1 + self.node_id,
                data=p.TPDO1_STRUCT.pack(sw, applied_pm, counts),
                is_extended_id=False,
            )
        ]
        if self.velocity_pdo:
            vel = round(self.plant.theta_dot[self.cable] * self.cpr / (2.0 * math.pi))
            out.append(
                can.Message(
                    arbitration_id=p.TPDO2 + self.node_id,
                    data=p.TPDO2_STRUCT.pack(vel),
                    is_extended_id=False,
                )
            )
        return out

    def _missed_sync_since_rpdo(self, data: bytes) -> bool:
        """Counts this SYNC; True when its counter (0x1019) says SYNCs were lost since the
        last one and fewer RPDOs came than were sent (one before each SYNC): the pending one
        may be for a SYNC this drive missed. Applied now, its target is a period late: the
        drive falls behind by a period and its catch-up over the next lost SYNC overshoots
        (5 % frame loss, rowc: 0.37 rad, a following-error fault). One more RPDO than lost
        SYNCs: the last one came after them, for this SYNC."""
        overflow = self.od[(p.OD_SYNC_COUNTER_OVERFLOW, 0)]
        received, self.rpdos_since_sync = self.rpdos_since_sync, 0
        if overflow < 2 or len(data) != 1:
            self.sync_count = 0
            return False
        previous, self.sync_count = self.sync_count, data[0]
        missed = (self.sync_count - previous - 1) % overflow if previous else 0
        return received <= missed

    def _apply_controlword(self, cw: int) -> None:
        cmd = p.command_of(cw)
        rising_reset = bool(cw & 0x80) and not bool(self.last_controlword & 0x80)
        self.last_controlword = cw
        if cmd is p.Command.FAULT_RESET and not rising_reset:
            return
        if cmd is p.Command.FAULT_RESET and self.state is p.PowerState.FAULT:
            self.fault_code = 0
        if cmd is None:
            return
        nxt = p.TRANSITIONS.get((self.state, cmd))
        if nxt is not None:
            if self.state is p.PowerState.READY_TO_SWITCH_ON and cmd is p.Command.ENABLE_OPERATION:
                self.state = p.PowerState.OPERATION_ENABLED  # 3 then 4 in one step
                self.transitions += [3, 4]
            else:
                self.state, number = nxt
                self.transitions.append(number)

    def _apply_to_plant(self, interval: float = math.inf, fresh: bool = True) -> None:
        """``interval`` (s): since the last SYNC; ``fresh``: a new target came with this SYNC
        (without one, position mode goes on at the target's last rate, as across a late SYNC:
        stopping the target for a period and catching up after made a following error of
        a period's travel at every lost frame)."""
        c, servo, plant = self.cable, self.plant.servo, self.plant
        if self.state is p.PowerState.OPERATION_ENABLED:
            tau = self.torque_pm * self.rated_torque / 1000.0
            tau = max(-self.torque_limit, min(self.torque_limit, tau))
            plant.motor_torque[c] = tau
            if self.mode == p.MODE_CSP:
                theta = plant.theta[c]
                if servo.kp[c] <= 0.0:  # just enabled: the loop starts where the motor is
                    servo.target[c] = theta
                    servo.rate[c] = 0.0
                if self.target_counts is not None and fresh:
                    now = self._counts()
                    step = ((self.target_counts - now + 0x80000000) & 0xFFFFFFFF) - 0x80000000
                    end = theta + step * 2.0 * math.pi / self.cpr
                    # reach it one SYNC period from now (the drive's estimate of the period);
                    # after a long gap, a step
                    if 0.0 <= interval < self.EXTRAPOLATE_FOR and self.sync_period > 0.0:
                        servo.rate[c] = (end - servo.target[c]) / self.sync_period
                    else:
                        servo.target[c], servo.rate[c] = end, 0.0
                servo.kp[c], servo.kd[c] = self.position_gains
            else:
                servo.kp[c] = 0.0
            plant.brake[c] = False
        else:  # disabled, quick stop, fault: no torque, the brake holds the drum
            plant.motor_torque[c] = 0.0
            servo.kp[c] = 0.0
            servo.beyond[c] = 0.0
            self.target_counts = None
            plant.brake[c] = True

    def _measure_sync_period(self, interval: float) -> None:
        """``sync_period`` (s): the SYNC period as a drive locks to it, the median of the last
        ``SYNC_WINDOW`` intervals: a late SYNC or two at once do not move it, a new rate (set-up
        to cycling) takes half the window. Interpolating over the last interval instead, SYNCs
        handled late by a loaded simulator (two in one step: an interval of 0) made a target
        step and a following-error fault mid-move."""
        if not 0.0 <= interval < self.EXTRAPOLATE_FOR:
            return
        self._intervals.append(interval)
        del self._intervals[: -self.SYNC_WINDOW]
        ordered = sorted(self._intervals)
        self.sync_period = ordered[len(ordered) // 2]

    SYNC_WINDOW = 9

    def jump_encoder(self, counts: int) -> None:
        """Fault injection: the encoder jumps by ``counts``. In position mode the drive's loop
        sees it at once: its target, in the true motor angle, moves the other way."""
        self.encoder_offset += counts
        if self.state is p.PowerState.OPERATION_ENABLED and self.mode == p.MODE_CSP:
            self.plant.servo.target[self.cable] -= counts * 2.0 * math.pi / self.cpr

    def _counts(self) -> int:
        """Position actual (counts, 32-bit): the encoder, with an injected jump."""
        counts = round(self.plant.theta[self.cable] * self.cpr / (2.0 * math.pi))
        counts += self.encoder_offset
        return ((counts + 0x80000000) & 0xFFFFFFFF) - 0x80000000

    # s: how long the position target goes on at its last rate without a new one (a SYNC or an
    # RPDO late or lost) before the drive holds it
    EXTRAPOLATE_FOR = 0.05

    # -- time passing ---------------------------------------------------------------------------
    def tick(self, t: float) -> list[can.Message]:
        """Heartbeat when due; the position target held after ``EXTRAPOLATE_FOR`` without a
        SYNC; the communication timeout (drive-side safety)."""
        out: list[can.Message] = []
        servo = self.plant.servo
        if t - self.last_target > self.EXTRAPOLATE_FOR:
            servo.rate[self.cable] = 0.0
        if self.state is p.PowerState.OPERATION_ENABLED and following_error_py(servo, self.cable):
            emcy = self.inject_fault(p.EMCY_FOLLOWING_ERROR)
            if not self.silent:
                out.append(emcy)
        if self.state is p.PowerState.OPERATION_ENABLED and t - self.last_rx > self.comm_timeout:
            option = self.od[(p.OD_ABORT_CONNECTION, 0)]
            self.state = (
                p.PowerState.QUICK_STOP_ACTIVE if option == 3 else p.PowerState.SWITCH_ON_DISABLED
            )
            self.transitions.append(11 if option == 3 else 9)
            self._apply_to_plant()
            if not self.silent:
                out.append(self._emcy(0x8130))
        hb_ms = self.od[(p.OD_PRODUCER_HEARTBEAT, 0)]
        if hb_ms > 0 and not self.silent and t - self.last_hb >= hb_ms / 1000.0 - 1e-9:
            out.append(
                can.Message(
                    arbitration_id=p.HEARTBEAT + self.node_id,
                    data=bytes([self.nmt]),
                    is_extended_id=False,
                )
            )
            self.last_hb = t
        return out

    def inject_fault(self, code: int) -> can.Message:
        """A drive fault: FAULT state (brake), and its EMCY."""
        self.state = p.PowerState.FAULT
        self.transitions.append(13)
        self.fault_code = code
        self._apply_to_plant()
        return self._emcy(code)

    def _emcy(self, code: int) -> can.Message:
        return can.Message(
            arbitration_id=p.EMCY + self.node_id,
            data=p.EMCY_STRUCT.pack(code, 0x01, b"\0" * 5),
            is_extended_id=False,
        )
