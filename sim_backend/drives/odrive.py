"""An ODrive axis (CAN Simple) as the simulator's CAN node.

Answers Set_Controller_Mode, Set_Axis_State (IDLE: brake; CLOSED_LOOP_CONTROL: torque
applied), Set_Input_Torque (applied at once: the protocol has no SYNC), Clear_Errors, Estop;
streams heartbeat and encoder estimates and torques at every simulation step it is ticked
(the cyclic messages an ODrive is configured to send); the watchdog (comm timeout) drops the
axis to IDLE with the watchdog error bit.
"""

from __future__ import annotations

import math

import can

from drivers.odrive import protocol as p
from sim_backend.plant import CdprPlant

WATCHDOG_EXPIRED = 0x01000000
HEARTBEAT_PERIOD = 0.1  # s


class ODriveAxis:
    def __init__(
        self, node_id: int, cable: int, plant: CdprPlant, torque_limit: float, comm_timeout: float
    ):
        self.node_id = node_id
        self.cable = cable
        self.plant = plant
        self.torque_limit = torque_limit
        self.comm_timeout = comm_timeout
        self.state = p.AxisState.IDLE
        self.control_mode = 0
        self.error = 0
        self.torque_cmd = 0.0
        self.last_rx = -math.inf
        self.last_hb = -math.inf
        self.silent = False
        self.encoder_offset = 0.0  # rad, fault injection

    def _msg(self, cmd: int, data: bytes) -> can.Message:
        return can.Message(
            arbitration_id=p.arbitration_id(self.node_id, cmd), data=data, is_extended_id=False
        )

    def on_frame(self, cmd: int, data: bytes, remote: bool, t: float) -> list[can.Message]:
        self.last_rx = t
        if cmd == p.SET_INPUT_TORQUE and len(data) >= 4:
            self.torque_cmd = p.TORQUE_STRUCT.unpack(data[:4])[0]
        elif cmd == p.SET_AXIS_STATE and len(data) >= 4:
            want = p.U32_STRUCT.unpack(data[:4])[0]
            if (
                want == p.AxisState.CLOSED_LOOP_CONTROL
                and self.error == 0
                and (self.control_mode == p.CONTROL_MODE_TORQUE)
            ):
                self.state = p.AxisState.CLOSED_LOOP_CONTROL
            elif want == p.AxisState.IDLE:
                self.state = p.AxisState.IDLE
        elif cmd == p.SET_CONTROLLER_MODE and len(data) >= 8:
            self.control_mode = p.MODE_STRUCT.unpack(data[:8])[0]
        elif cmd == p.CLEAR_ERRORS:
            self.error = 0
        elif cmd == p.ESTOP:
            self.inject_fault(0x02000000)
        self._apply()
        return []

    def _apply(self) -> None:
        c = self.cable
        if self.state is p.AxisState.CLOSED_LOOP_CONTROL and self.error == 0:
            self.plant.motor_torque[c] = max(
                -self.torque_limit, min(self.torque_limit, self.torque_cmd)
            )
            self.plant.brake[c] = False
        else:
            self.plant.motor_torque[c] = 0.0
            self.plant.close_brake(c)

    def tick(self, t: float) -> list[can.Message]:
        if self.state is p.AxisState.CLOSED_LOOP_CONTROL and t - self.last_rx > self.comm_timeout:
            self.inject_fault(WATCHDOG_EXPIRED)
        self._apply()
        if self.silent:
            return []
        out = []
        pos = (self.plant.theta[self.cable] + self.encoder_offset) / (2.0 * math.pi)
        vel = self.plant.theta_dot[self.cable] / (2.0 * math.pi)
        out.append(self._msg(p.GET_ENCODER_ESTIMATES, p.ENCODER_STRUCT.pack(pos, vel)))
        applied = self.plant.motor_torque[self.cable]
        out.append(self._msg(p.GET_TORQUES, p.TORQUES_STRUCT.pack(self.torque_cmd, applied)))
        if t - self.last_hb >= HEARTBEAT_PERIOD - 1e-9:
            out.append(
                self._msg(p.HEARTBEAT, p.HEARTBEAT_STRUCT.pack(self.error, int(self.state), 0, 1))
            )
            self.last_hb = t
        return out

    def inject_fault(self, code: int) -> can.Message:
        self.error |= code
        self.state = p.AxisState.IDLE
        self._apply()
        return self._msg(p.HEARTBEAT, p.HEARTBEAT_STRUCT.pack(self.error, int(self.state), 0, 0))
