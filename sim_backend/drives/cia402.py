"""A CiA 402 drive as the simulator's CAN node: it answers the frames a real drive answers.

The CiA 301 node is here: NMT (pre-operational → operational on "start", boot-up after a
reset), the object dictionary of the shipped EDS served by canopen's SDO server
(``dictionary.py``), its PDOs as its mapping objects say (``pdo.PdoEngine``: RPDO1 latched and
applied at the next SYNC, TPDOs sampled at the SYNC), the SYNC as it sees it
(``sync_clock.py``), heartbeat production (0x1017), EMCY on faults, and the communication
timeout, which triggers the abort-connection option (0x6007). The CiA 402 axis it carries is
``axis.Cia402Axis``: the power state machine, cyclic synchronous torque (mode 10) or position
(mode 8), the torque limit, the following error in position mode (beyond 0x6065 for longer
than 0x6066: FAULT, EMCY 0x8611), the brake that holds the drum while not enabled, the encoder.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import can
from canopen import SdoAbortedError

from drivers.cia402 import protocol as p
from sim_backend.drives import pdo
from sim_backend.drives.axis import OD_STO_INPUTS, Cia402Axis
from sim_backend.drives.dictionary import NMT_RESETS, NMT_STATE_OF, Dictionary
from sim_backend.drives.sync_clock import SyncClock
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
        position_gains: tuple[float, float],
        rpdo_owners: dict[int, Cia402Drive],
        target_extrapolation: float,
    ):
        self.node_id = node_id
        # COB-ID → drive, shared by the drives of one bus: who takes an RPDO (the network's
        # dispatch; kept by each drive as its RPDO's COB-ID changes)
        self.rpdo_owners = rpdo_owners
        self.cable = cable
        self.comm_timeout = comm_timeout
        self.sync = SyncClock(target_extrapolation)  # the SYNC as this drive sees it
        self.stale_targets = 0  # RPDOs not taken: they were for a SYNC this drive missed
        self.nmt = p.HB_PRE_OPERATIONAL
        # the object dictionary of the shipped EDS; this drive's stored parameters over its
        # defaults: its rated torque and its torque limit (per mille of rated)
        limit_pm = min(0xFFFF, round(torque_limit / rated_torque * 1000.0))
        self.dictionary = Dictionary(
            node_id,
            {(p.OD_RATED_TORQUE, 0): round(rated_torque * 1000.0), (p.OD_MAX_TORQUE, 0): limit_pm},
            self._read_object,
            self._check_object,
            self._object_written,
        )
        self.od = self.dictionary.values  # (index, sub) → value, typed by the dictionary
        self.axis = Cia402Axis(cable, plant, self.od, rated_torque, counts_per_rev,
                               torque_limit, position_gains, target_extrapolation)  # fmt: skip
        a = self.axis
        # the objects whose value is the drive's state, read when asked (SDO) or sent (TPDO)
        self._live: dict[int, Callable[[], int]] = {
            p.OD_STATUSWORD: lambda: p.STATUSWORD_OF[a.state],
            p.OD_MODES_DISPLAY: lambda: a.mode,
            p.OD_POSITION_ACTUAL: a.counts,
            p.OD_VELOCITY_ACTUAL: a.velocity_counts,
            p.OD_TORQUE_ACTUAL: a.torque_actual_pm,
            # bit 0: generic error
            p.OD_ERROR_REGISTER: lambda: int(a.state is p.PowerState.FAULT),
            p.OD_ERROR_CODE: lambda: a.fault_code,
            p.OD_CONTROLWORD: lambda: a.last_controlword,
        }
        # RPDO1 and the TPDOs as this drive's mapping objects say (CiA 301's PDO engine)
        self.pdos = pdo.PdoEngine(self.dictionary, self._live, _RPDO_SLOTS, self.rpdo_owners, self)
        # the RPDO latched for the next SYNC: (controlword, target torque per mille, target
        # position counts, torque offset per mille), None where not mapped
        self.pending: tuple[int | None, int | None, int | None, int | None] | None = None
        self.last_rx = -math.inf  # last RPDO or SYNC
        self.last_hb = -math.inf
        self.silent = False  # fault injection: the drive stops talking
        self.axis.set_following_error()

    # -- frames in ------------------------------------------------------------------------------
    def on_nmt(self, command: int) -> list[can.Message]:
        """NMT (CiA 301 §7.3.2): the state; a reset restores the objects (node: all of them,
        the drive's state machine restarted; communication: 0x1000-0x1FFF) and ends with
        the boot-up message, in PRE-OPERATIONAL."""
        if command in NMT_STATE_OF:
            self.nmt = NMT_STATE_OF[command]
        elif command in NMT_RESETS:
            self.dictionary.reset_by(command)
            if command == p.NMT_RESET_NODE:
                self.axis.reset()
            self.axis.set_following_error()
            self.pdos.compile()
            self.nmt = p.HB_PRE_OPERATIONAL
            self.pending = None
            self.sync.count = 0
            self.last_hb = -math.inf
            if not self.silent:
                return [self._heartbeat_frame(p.HB_BOOTUP)]
        return []

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
        elif index == p.OD_MODES_OF_OPERATION and not self.axis.supports_mode(value):
            raise SdoAbortedError(0x06090030)  # value range exceeded: not in 0x6502
        elif index == p.OD_ABORT_CONNECTION and value > p.ABORT_CONNECTION_QUICK_STOP:
            raise SdoAbortedError(0x06090031)  # value too high

    def _object_written(self, index: int, sub: int, value: int) -> None:
        """A stored download's effect on the drive."""
        if pdo.is_pdo_object(index):
            self.pdos.compile()
        if index in (p.OD_FOLLOWING_ERROR_WINDOW, p.OD_FOLLOWING_ERROR_TIMEOUT):
            self.axis.set_following_error()
        if index == p.OD_RATED_TORQUE and value > 0:
            self.axis.rated_torque = value / 1000.0

    def _read_object(self, index: int, sub: int) -> int | None:
        """A live object's value (an SDO upload), None for the stored ones."""
        if index == OD_STO_INPUTS and sub == 1:
            return self.axis.sto_inputs()
        live = self._live.get(index)
        return None if live is None else live()

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
            cw, torque, position, offset = pending
            if cw is not None:
                self.axis.apply_controlword(cw)
            fresh = self.axis.take(t, torque, position, offset)
        self.axis.apply(interval, fresh, self.sync.period)
        if self.silent:
            return []
        return self.pdos.tpdos()

    def boot_up(self) -> list[can.Message]:
        """The boot-up message a drive sends once it is powered on (none while silent)."""
        return [] if self.silent else [self._heartbeat_frame(p.HB_BOOTUP)]

    def power_cycle(self) -> list[can.Message]:
        """Fault injection: the drive loses power and boots (brake on, objects to their
        defaults, an incremental counter at zero, the boot-up message)."""
        return self.on_nmt(p.NMT_RESET_NODE)

    # -- time passing ---------------------------------------------------------------------------
    def tick(self, t: float) -> list[can.Message]:
        """Heartbeat when due; the position target held after ``extrapolate_for`` without a
        new one (``holds_at``); the communication timeout (drive-side safety)."""
        out: list[can.Message] = []
        axis = self.axis
        axis.hold_if_due(t)
        if axis.following_error():
            emcy = self.inject_fault(p.EMCY_FOLLOWING_ERROR)
            if not self.silent:
                out.append(emcy)
        if axis.emcy_due is not None:  # switched on with the safety chain open
            if not self.silent:
                out.append(self._emcy(axis.emcy_due))
            axis.emcy_due = None
        if axis.state is p.PowerState.OPERATION_ENABLED and t - self.last_rx > self.comm_timeout:
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
        self.axis.connection_lost(option)
        return [] if self.silent else [self._emcy(0x8130)]

    def _heartbeat_frame(self, state: int) -> can.Message:
        return can.Message(
            arbitration_id=p.HEARTBEAT + self.node_id, data=bytes([state]), is_extended_id=False
        )

    def open_sto(self, code: int = p.EMCY_STO, t: float | None = None) -> list[can.Message]:
        """The safety chain at this drive's STO input opens at ``t`` (s;
        ``Cia402Axis.open_sto``): the EMCY where the drive faults."""
        faulted = self.axis.open_sto(code, t)
        return [self._emcy(code)] if faulted and not self.silent else []

    def close_sto(self) -> None:
        self.axis.close_sto()

    def inject_fault(self, code: int) -> can.Message:
        """A drive fault: FAULT state (brake), and its EMCY."""
        self.axis.fault(code)
        return self._emcy(code)

    def _emcy(self, code: int) -> can.Message:
        return can.Message(
            arbitration_id=p.EMCY + self.node_id,
            data=p.EMCY_STRUCT.pack(code, 0x01, b"\0" * 5),
            is_extended_id=False,
        )
