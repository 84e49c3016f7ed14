"""A CiA 402 drive as the simulator's CAN node: it answers the frames a real drive answers.

NMT (pre-operational → operational on "start", boot-up after a reset), the object dictionary
of the shipped EDS served by canopen's SDO server (``dictionary.py``), its PDOs as its mapping
objects say (``pdo.PdoEngine``: RPDO1 latched and applied at the next SYNC, TPDOs sampled at
the SYNC), the SYNC as it sees it (``sync_clock.py``), cyclic synchronous torque (mode 10) or
position (mode 8: the target interpolated linearly between SYNCs, the drive's own position
loop run at every physics step, ``physics.Servo``), the power state machine of CiA 402 (the
transition table of ``drivers.cia402.protocol``), heartbeat production (0x1017), EMCY on
faults, and drive-side safety: the communication timeout triggers the abort-connection option
(0x6007), the following error in position mode (beyond 0x6065 for longer than 0x6066: FAULT,
EMCY 0x8611), the torque limit, and the brake that holds the drum while not enabled.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import can
from canopen import SdoAbortedError

from drivers.cia402 import protocol as p
from sim_backend.drives import pdo
from sim_backend.drives.dictionary import Dictionary
from sim_backend.drives.sync_clock import SyncClock
from sim_backend.physics import following_error_py
from sim_backend.plant import CdprPlant

# what an RPDO carries, by object: its place in ``Cia402Drive.pending``
_RPDO_SLOTS = {p.OD_CONTROLWORD: 0, p.OD_TARGET_TORQUE: 1, p.OD_TARGET_POSITION: 2,
               p.OD_TORQUE_OFFSET: 3}  # fmt: skip


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
        position_gains: tuple[float, float] = (0.0, 0.0),
        rpdo_owners: dict[int, Cia402Drive] | None = None,
        target_extrapolation: float = 0.05,
    ):
        self.node_id = node_id
        # COB-ID → drive, shared by the drives of one bus: who takes an RPDO (the network's
        # dispatch; kept by each drive as its RPDO's COB-ID changes)
        self.rpdo_owners: dict[int, Cia402Drive] = {} if rpdo_owners is None else rpdo_owners
        self.cable = cable
        self.plant = plant
        self.rated_torque = rated_torque  # N·m per 1000 per-mille
        self.cpr = counts_per_rev
        self.torque_limit = torque_limit
        self.comm_timeout = comm_timeout
        # the position loop's gains in mode 8 (N·m/rad, N·m·s/rad): the drive's own tuning
        self.position_gains = position_gains
        # s: how long the position target goes on at its last rate without a new one (a SYNC or
        # an RPDO late or lost) before the drive holds it ([drives] target_extrapolation)
        self.extrapolate_for = target_extrapolation
        self.sync = SyncClock(target_extrapolation)  # the SYNC as this drive sees it
        self.stale_targets = 0  # RPDOs not taken: they were for a SYNC this drive missed
        self.last_target = -math.inf  # s, the SYNC that applied the last RPDO
        self.nmt = p.HB_PRE_OPERATIONAL
        self.state = p.PowerState.SWITCH_ON_DISABLED  # transitions 0 and 1 done at power-on
        # the object dictionary of the shipped EDS; this drive's stored parameters over its
        # defaults: its rated torque and its torque limit (per mille of rated)
        limit_pm = min(0xFFFF, round(torque_limit / rated_torque * 1000.0))
        # the objects whose value is the drive's state, read when asked (SDO) or sent (TPDO)
        self._live: dict[int, Callable[[], int]] = {
            p.OD_STATUSWORD: lambda: p.STATUSWORD_OF[self.state],
            p.OD_MODES_DISPLAY: lambda: self.mode,
            p.OD_POSITION_ACTUAL: self._counts,
            p.OD_VELOCITY_ACTUAL: lambda: round(
                self.plant.theta_dot[self.cable] * self.cpr / (2.0 * math.pi)
            ),
            p.OD_TORQUE_ACTUAL: self._torque_actual_pm,
            # bit 0: generic error
            p.OD_ERROR_REGISTER: lambda: int(self.state is p.PowerState.FAULT),
            p.OD_ERROR_CODE: lambda: self.fault_code,
            p.OD_CONTROLWORD: lambda: self.last_controlword,
        }
        self.dictionary = Dictionary(
            node_id,
            {(p.OD_RATED_TORQUE, 0): round(rated_torque * 1000.0), (p.OD_MAX_TORQUE, 0): limit_pm},
            self._read_object,
            self._check_object,
            self._object_written,
        )
        self.od = self.dictionary.values  # (index, sub) → value, typed by the dictionary
        # RPDO1 and the TPDOs as this drive's mapping objects say (CiA 301's PDO engine)
        self.pdos = pdo.PdoEngine(self.dictionary, self._live, _RPDO_SLOTS, self.rpdo_owners, self)
        # the RPDO latched for the next SYNC: (controlword, target torque per mille, target
        # position counts, torque offset per mille), None where not mapped
        self.pending: tuple[int | None, int | None, int | None, int | None] | None = None
        self.torque_pm = 0  # applied: the target torque (mode 10), the offset (mode 8)
        self.target_counts: int | None = None  # mode 8: the last target position
        self.last_controlword = 0
        self.last_rx = -math.inf  # last RPDO or SYNC
        self.last_hb = -math.inf
        self.fault_code = 0
        self.silent = False  # fault injection: the drive stops talking
        self.encoder_offset = 0  # counts, fault injection: an encoder jump
        # incremental encoder: the counter restarts at zero at power-up and at a reset node;
        # ``encoder_zero`` is the motor angle (counts) it restarted at. Absolute: kept (0)
        self.incremental = False
        self.encoder_zero = 0
        self.transitions: list[int] = []  # CiA 402 transition numbers taken (for tests)
        self._set_following_error()

    # -- frames in ------------------------------------------------------------------------------
    def on_nmt(self, command: int) -> list[can.Message]:
        """NMT (CiA 301 §7.3.2): the state; a reset restores the objects (node: all of them,
        the drive's state machine restarted; communication: 0x1000-0x1FFF) and ends with
        the boot-up message, in PRE-OPERATIONAL."""
        if command == p.NMT_START:
            self.nmt = p.HB_OPERATIONAL
        elif command == p.NMT_STOP:
            self.nmt = p.HB_STOPPED
        elif command == p.NMT_PRE_OPERATIONAL:
            self.nmt = p.HB_PRE_OPERATIONAL
        elif command in (p.NMT_RESET_NODE, p.NMT_RESET_COMMUNICATION):
            if command == p.NMT_RESET_NODE:
                self.dictionary.reset(0x0000, 0x10000)
                self.state = p.PowerState.SWITCH_ON_DISABLED
                self.fault_code = 0
                self._apply_to_plant()
                if self.incremental:
                    self.zero_counter()
            else:
                self.dictionary.reset(0x1000, 0x2000)
            self._set_following_error()
            self.pdos.compile()
            self.nmt = p.HB_PRE_OPERATIONAL
            self.pending = None
            self.sync.count = 0
            self.last_hb = -math.inf
            if not self.silent:
                return [self._heartbeat_frame(p.HB_BOOTUP)]
        return []

    @property
    def mode(self) -> int:
        return self.od[(p.OD_MODES_OF_OPERATION, 0)]

    def on_rpdo(self, data: bytes, t: float) -> None:
        """An RPDO as its mapping says, latched for the next SYNC (transmission types 0-240;
        254/255 would act at once: not used by cdprctl, not offered here). Shorter than its
        mapping: not processed (CiA 301: a length error)."""
        if self.nmt != p.HB_OPERATIONAL:
            return
        latched = self.pdos.decode_rpdo(data)
        if latched is None:  # not valid, or shorter than its mapping
            return
        cw, torque, position, offset = latched
        self.pending = (cw, torque, position, offset)
        self.sync.rpdos += 1
        self.last_rx = t

    def on_sdo(self, data: bytes) -> can.Message | None:
        """The SDO server's answer (CiA 301 §7.2.4; not in NMT STOPPED)."""
        if len(data) != 8 or self.silent or self.nmt == p.HB_STOPPED:
            return None
        return self.dictionary.request(p.SDO_RX + self.node_id, data)

    def _check_object(self, index: int, sub: int, value: int) -> None:
        """An SDO download, before it is stored: refused with CiA 301's abort code."""
        if pdo.is_pdo_object(index):
            operational = self.nmt == p.HB_OPERATIONAL
            pdo.check_write(self.dictionary.od, self.od, operational, index, sub, value)
        elif index == p.OD_MODES_OF_OPERATION and not self.supports_mode(value):
            raise SdoAbortedError(0x06090030)  # value range exceeded: not in 0x6502
        elif index == p.OD_ABORT_CONNECTION and value > p.ABORT_CONNECTION_QUICK_STOP:
            raise SdoAbortedError(0x06090031)  # value too high

    def _object_written(self, index: int, sub: int, value: int) -> None:
        """A stored download's effect on the drive."""
        if pdo.is_pdo_object(index):
            self.pdos.compile()
        if index == p.OD_MODES_OF_OPERATION:
            self.od[(p.OD_MODES_DISPLAY, 0)] = value  # switched at once
        if index in (p.OD_FOLLOWING_ERROR_WINDOW, p.OD_FOLLOWING_ERROR_TIMEOUT):
            self._set_following_error()
        if index == p.OD_RATED_TORQUE and value > 0:
            self.rated_torque = value / 1000.0

    def supports_mode(self, mode: int) -> bool:
        """0x6502: bit 7 cyclic synchronous position, bit 9 torque (CiA 402 §6.4.7)."""
        bit = p.SUPPORTED_MODE_BIT.get(mode)
        return bit is not None and bool(self.od[(p.OD_SUPPORTED_DRIVE_MODES, 0)] >> bit & 1)

    def _read_object(self, index: int, sub: int) -> int | None:
        """A live object's value (an SDO upload), None for the stored ones."""
        live = self._live.get(index)
        return None if live is None else live()

    @property
    def effective_torque_limit(self) -> float:
        """N·m: the winch's limit, or 0x6072 (per mille of the rated torque) if lower."""
        max_torque = self.od[(p.OD_MAX_TORQUE, 0)] * self.rated_torque / 1000.0
        return min(self.torque_limit, max_torque)

    def _torque_actual_pm(self) -> int:
        """0x6077 (per mille of rated): the torque the drive applies, after its limit."""
        if self.state is not p.PowerState.OPERATION_ENABLED:
            return 0
        c = self.cable
        # in position mode, what its loop applies now
        csp = self.mode == p.MODE_CSP
        tau = self.plant.servo.applied[c] if csp else self.plant.motor_torque[c]
        return max(-32767, min(32767, round(tau * 1000.0 / self.rated_torque)))

    def _set_following_error(self) -> None:
        """The position loop's following-error window (rad) and time-out (s) from 0x6065 and
        0x6066: set when they are written, not at every SYNC."""
        window = self.od[(p.OD_FOLLOWING_ERROR_WINDOW, 0)] & 0xFFFFFFFF
        servo, c = self.plant.servo, self.cable
        off = window == p.FOLLOWING_ERROR_OFF
        servo.window[c] = math.inf if off else window * 2.0 * math.pi / self.cpr
        servo.timeout[c] = self.od[(p.OD_FOLLOWING_ERROR_TIMEOUT, 0)] / 1000.0

    def on_sync(self, t: float, data: bytes = b"") -> list[can.Message]:
        """Apply the latched RPDO, then sample and send the TPDOs."""
        self.last_rx = t
        interval = self.sync.sync(t)
        stale = self.sync.missed_since_rpdo(data, self.od[(p.OD_SYNC_COUNTER_OVERFLOW, 0)])
        if self.nmt != p.HB_OPERATIONAL:
            return []
        pending, self.pending = self.pending, None
        if pending is not None and stale:
            pending = None  # not taken: as across a lost RPDO, the target goes on
            self.stale_targets += 1
        fresh = False
        if pending is not None:
            self.last_target = t
            cw, torque, position, offset = pending
            if cw is not None:
                self._apply_controlword(cw)
            if self.mode == p.MODE_CSP:
                fresh = position is not None
                if fresh:
                    self.target_counts = position
                self.torque_pm = offset if offset is not None else 0
            elif torque is not None:
                self.torque_pm = torque
        self._apply_to_plant(interval, fresh)
        if self.silent:
            return []
        return self.pdos.tpdos()

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
            limit = self.effective_torque_limit
            tau = max(-limit, min(limit, tau))
            plant.motor_torque[c] = tau
            servo.limit[c] = limit
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
                    period = self.sync.period
                    if 0.0 <= interval < self.extrapolate_for and period > 0.0:
                        servo.rate[c] = (end - servo.target[c]) / period
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

    def jump_encoder(self, counts: int) -> None:
        """Fault injection: the encoder jumps by ``counts``. In position mode the drive's loop
        sees it at once: its target, in the true motor angle, moves the other way."""
        self.encoder_offset += counts
        if self.state is p.PowerState.OPERATION_ENABLED and self.mode == p.MODE_CSP:
            self.plant.servo.target[self.cable] -= counts * 2.0 * math.pi / self.cpr

    def zero_counter(self) -> None:
        """An incremental encoder's counter restarting (power-up, reset node): it reads zero
        wherever the motor stands."""
        self.encoder_zero = round(self.plant.theta[self.cable] * self.cpr / (2.0 * math.pi))

    def power_cycle(self) -> list[can.Message]:
        """Fault injection: the drive loses power and boots (brake on, objects to their
        defaults, an incremental counter at zero, the boot-up message)."""
        return self.on_nmt(p.NMT_RESET_NODE)

    def _counts(self) -> int:
        """Position actual (counts, 32-bit): the encoder from its zero, with an injected
        jump."""
        counts = round(self.plant.theta[self.cable] * self.cpr / (2.0 * math.pi))
        counts += self.encoder_offset - self.encoder_zero
        return ((counts + 0x80000000) & 0xFFFFFFFF) - 0x80000000

    # -- time passing ---------------------------------------------------------------------------
    def holds_at(self) -> float:
        """s: when the position target stops going on at its last rate, ``extrapolate_for``
        after the last new one (inf: it is not moving)."""
        moving = self.plant.servo.rate[self.cable] != 0.0
        return self.last_target + self.extrapolate_for if moving else math.inf

    def tick(self, t: float) -> list[can.Message]:
        """Heartbeat when due; the position target held after ``extrapolate_for`` without a
        new one (``holds_at``); the communication timeout (drive-side safety)."""
        out: list[can.Message] = []
        servo = self.plant.servo
        if t >= self.holds_at():
            servo.rate[self.cable] = 0.0
        if self.state is p.PowerState.OPERATION_ENABLED and following_error_py(servo, self.cable):
            emcy = self.inject_fault(p.EMCY_FOLLOWING_ERROR)
            if not self.silent:
                out.append(emcy)
        if self.state is p.PowerState.OPERATION_ENABLED and t - self.last_rx > self.comm_timeout:
            out += self._connection_lost()
        hb_ms = self.od[(p.OD_PRODUCER_HEARTBEAT, 0)]
        if hb_ms > 0 and not self.silent and t - self.last_hb >= hb_ms / 1000.0 - 1e-9:
            out.append(self._heartbeat_frame(self.nmt))
            self.last_hb = t
        return out

    def _connection_lost(self) -> list[can.Message]:
        """The abort-connection option code (0x6007, CiA 402 §6.4.1): 0 no action, 1 fault
        signal (FAULT), 2 disable voltage, 3 quick stop; EMCY 0x8130 (life guard or
        heartbeat error) whatever the reaction."""
        option = self.od[(p.OD_ABORT_CONNECTION, 0)]
        if option == 0:
            return []
        if option == 2:
            self.state = p.PowerState.SWITCH_ON_DISABLED
            self.transitions.append(9)
        elif option == p.ABORT_CONNECTION_QUICK_STOP:
            self.state = p.PowerState.QUICK_STOP_ACTIVE
            self.transitions.append(11)
        else:  # 1 and the manufacturer-specific negative codes: the fault reaction
            self.state = p.PowerState.FAULT
            self.transitions.append(13)
            self.fault_code = 0x8130
        self._apply_to_plant()
        return [] if self.silent else [self._emcy(0x8130)]

    def _heartbeat_frame(self, state: int) -> can.Message:
        return can.Message(
            arbitration_id=p.HEARTBEAT + self.node_id, data=bytes([state]), is_extended_id=False
        )

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
