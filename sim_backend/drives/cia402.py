"""A CiA 402 drive as the simulator's CAN node: it answers the frames a real drive answers.

NMT (pre-operational → operational on "start"), SDO server (expedited) for the objects the
driver configures, RPDO1 latched and applied at the next SYNC (CiA 301 synchronous PDO), TPDO1
(and TPDO2) sampled at the SYNC, the power state machine of CiA 402 (the transition table of
``drivers.cia402.protocol``), heartbeat production (0x1017), EMCY on faults, and drive-side
safety: the communication timeout triggers the abort-connection option (0x6007: quick stop),
the torque limit, and the brake that holds the drum whenever the drive is not enabled.
"""

from __future__ import annotations

import math

import can

from drivers.cia402 import protocol as p
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
    ):
        self.node_id = node_id
        self.velocity_pdo = velocity_pdo  # TPDO2 (0x606C) mapped and sent on SYNC
        self.cable = cable
        self.plant = plant
        self.rated_torque = rated_torque  # N·m per 1000 per-mille
        self.cpr = counts_per_rev
        self.torque_limit = torque_limit
        self.comm_timeout = comm_timeout
        self.nmt = p.HB_PRE_OPERATIONAL
        self.state = p.PowerState.SWITCH_ON_DISABLED  # transitions 0 and 1 done at power-on
        self.od: dict[tuple[int, int], int] = {
            (p.OD_MODES_OF_OPERATION, 0): 0,
            (p.OD_MODES_DISPLAY, 0): 0,
            (p.OD_PRODUCER_HEARTBEAT, 0): 0,
            (p.OD_ABORT_CONNECTION, 0): 1,
            (p.OD_RATED_TORQUE, 0): round(rated_torque * 1000),
        }
        self.pending: tuple[int, int] | None = None  # (controlword, torque per-mille)
        self.torque_pm = 0  # applied
        self.last_controlword = 0
        self.last_rx = -math.inf  # last RPDO or SYNC
        self.last_hb = -math.inf
        self.fault_code = 0
        self.silent = False  # fault injection: the drive stops talking
        self.encoder_offset = 0  # counts, fault injection: an encoder jump
        self.transitions: list[int] = []  # CiA 402 transition numbers taken (for tests)

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

    def on_rpdo(self, data: bytes, t: float) -> None:
        if self.nmt != p.HB_OPERATIONAL or len(data) != 4:
            return
        self.pending = p.RPDO1_STRUCT.unpack(data)
        self.last_rx = t

    def on_sdo(self, data: bytes) -> can.Message | None:
        if len(data) != 8 or self.silent:
            return None
        cmd, index, sub, raw = p.SDO_STRUCT.unpack(data)
        key = (index, sub)
        if cmd & 0xE0 == 0x20:  # download (expedited)
            size = 4 - ((cmd >> 2) & 0x3) if cmd & 0x1 else 4
            value = int.from_bytes(raw[:size], "little", signed=True)
            if key not in self.od or key == (p.OD_MODES_DISPLAY, 0):
                return self._sdo_abort(index, sub, 0x06020000 if key not in self.od else 0x06010002)
            self.od[key] = value
            if key == (p.OD_MODES_OF_OPERATION, 0):
                self.od[(p.OD_MODES_DISPLAY, 0)] = value
            return self._sdo_answer(p.SDO_STRUCT.pack(0x60, index, sub, b"\0\0\0\0"))
        if cmd & 0xE0 == 0x40:  # upload
            if key not in self.od:
                return self._sdo_abort(index, sub, 0x06020000)
            value = self.od[key]
            return self._sdo_answer(
                p.SDO_STRUCT.pack(0x43, index, sub, (value & 0xFFFFFFFF).to_bytes(4, "little"))
            )
        return self._sdo_abort(index, sub, 0x05040001)

    def _sdo_answer(self, data: bytes) -> can.Message:
        return can.Message(arbitration_id=p.SDO_TX + self.node_id, data=data, is_extended_id=False)

    def _sdo_abort(self, index: int, sub: int, code: int) -> can.Message:
        return self._sdo_answer(p.SDO_STRUCT.pack(0x80, index, sub, code.to_bytes(4, "little")))

    def on_sync(self, t: float) -> list[can.Message]:
        """Apply the latched RPDO, then sample and send the TPDOs."""
        self.last_rx = t
        if self.nmt != p.HB_OPERATIONAL:
            return []
        if self.pending is not None:
            cw, tq = self.pending
            self.pending = None
            self._apply_controlword(cw)
            self.torque_pm = tq
        self._apply_to_plant()
        if self.silent:
            return []
        theta = self.plant.theta[self.cable]
        counts = round(theta * self.cpr / (2.0 * math.pi)) + self.encoder_offset
        counts = ((counts + 0x80000000) & 0xFFFFFFFF) - 0x80000000
        applied_pm = self.torque_pm if self.state is p.PowerState.OPERATION_ENABLED else 0
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

    def _apply_to_plant(self) -> None:
        c = self.cable
        if self.state is p.PowerState.OPERATION_ENABLED:
            tau = self.torque_pm * self.rated_torque / 1000.0
            tau = max(-self.torque_limit, min(self.torque_limit, tau))
            self.plant.motor_torque[c] = tau
            self.plant.brake[c] = False
        else:  # disabled, quick stop, fault: no torque, the brake holds the drum
            self.plant.motor_torque[c] = 0.0
            self.plant.brake[c] = True

    # -- time passing ---------------------------------------------------------------------------
    def tick(self, t: float) -> list[can.Message]:
        """Heartbeat when due; the communication timeout (drive-side safety)."""
        out: list[can.Message] = []
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
