"""ODrive axes in torque control over CAN Simple, sharing everything above the protocol.

Set-up sends Set_Controller_Mode (torque, passthrough); enabling is Set_Axis_State
CLOSED_LOOP_CONTROL, disabling IDLE, fault reset Clear_Errors. The axes stream their
heartbeat, encoder estimates and torques cyclically (configured on the ODrive); the cyclic
``write`` sends Set_Input_Torque to each axis.
"""

from __future__ import annotations

import math
from typing import Any

import can
import numpy as np

from drivers import blocking
from drivers.canbase import CanWinchDriver
from drivers.errors import DriveFaultError, DriverError
from drivers.odrive import protocol as p
from drivers.registry import register_driver
from drivers.vocabulary import DriveState

TWO_PI = 2.0 * math.pi


@register_driver
class ODriveDriver(CanWinchDriver):
    name = "odrive"
    drive_label = "ODrive axis"
    feedback_label = "encoder estimate"

    def __init__(self, model: Any, **kwargs: Any):
        super().__init__(model, **kwargs)
        m = self.m
        for c in range(m):
            b, n = int(self.bus_of[c]), int(self.node[c])
            for cmd in (p.HEARTBEAT, p.GET_ENCODER_ESTIMATES, p.GET_TORQUES):
                self._dispatch[(b, p.arbitration_id(n, cmd))] = (cmd, c)
        self._torque_msg = [
            can.Message(
                arbitration_id=p.arbitration_id(int(self.node[c]), p.SET_INPUT_TORQUE),
                data=bytearray(4),
                is_extended_id=False,
            )
            for c in range(m)
        ]
        self.axis_state = [p.AxisState.UNDEFINED] * m
        self.axis_error = np.zeros(m, dtype=np.int64)
        self._enable: bool | None = None
        self._enable_sent: bool | None = None
        self._enable_sent_at = -math.inf
        self._clear = False

    def _send_cmd(self, c: int, cmd: int, data: bytes) -> None:
        self._send(
            int(self.bus_of[c]),
            can.Message(
                arbitration_id=p.arbitration_id(int(self.node[c]), cmd),
                data=data,
                is_extended_id=False,
            ),
        )

    def _configure_drives(self, timeout: float) -> None:
        for c in range(self.m):
            self._send_cmd(
                c,
                p.SET_CONTROLLER_MODE,
                p.MODE_STRUCT.pack(p.CONTROL_MODE_TORQUE, p.INPUT_MODE_PASSTHROUGH),
            )
            self._send_cmd(c, p.SET_AXIS_STATE, p.U32_STRUCT.pack(p.AxisState.IDLE))
        lv = self.liveness
        lv.started = True
        blocking.await_first_feedback(
            self,
            timeout,
            lambda: bool(np.all(np.isfinite(lv.fb_stamp)) and np.all(np.isfinite(lv.last_hb))),
            "encoder estimates (ODrive axes)",
        )

    def _request_enable(self, enable: bool) -> None:
        self._enable = enable

    def _fault_reset(self) -> None:
        self._clear = True

    def _drain(self, t: float) -> None:
        for cmd, c, data in self._frames():
            if cmd == p.GET_ENCODER_ESTIMATES and len(data) == 8:
                pos, vel = p.ENCODER_STRUCT.unpack(data)
                step = pos * TWO_PI - self.states.position[c]
                if not (math.isfinite(pos) and math.isfinite(vel)) or not self.liveness.plausible(
                    c, step, t
                ):
                    continue  # a corrupted frame: dropped whole, like a lost one
                self.states.position[c] = pos * TWO_PI
                self.states.velocity[c] = vel * TWO_PI
                self.liveness.fresh[c] = True
                self.liveness.fb_stamp[c] = t
            elif cmd == p.GET_TORQUES and len(data) == 8:
                self.states.torque[c] = p.TORQUES_STRUCT.unpack(data)[1]
            elif cmd == p.HEARTBEAT and len(data) >= 7:
                err, state = p.HEARTBEAT_STRUCT.unpack(bytes(data).ljust(8, b"\0"))[:2]
                self.axis_error[c] = err
                try:
                    self.axis_state[c] = p.AxisState(state)
                except ValueError:
                    self.axis_state[c] = p.AxisState.UNDEFINED
                self.liveness.last_hb[c] = t
            else:
                self.stats.frames_ignored += 1

    def _update_states(self) -> bool:
        """Each axis's state from its heartbeat (``_cable_fault``, cable by cable)."""
        return any([self._cable_fault(c) is not None for c in range(self.m)])

    def _cable_fault(self, c: int) -> DriverError | None:
        st = self.states
        code = int(self.axis_error[c])
        st.fault_code[c] = code
        if code:
            st.state[c] = DriveState.FAULT
        elif self.axis_state[c] is p.AxisState.CLOSED_LOOP_CONTROL:
            st.state[c] = DriveState.ENABLED
        elif self.axis_state[c] is p.AxisState.IDLE:
            st.state[c] = DriveState.DISABLED
        else:
            st.state[c] = DriveState.UNKNOWN
        if code:
            return DriveFaultError(c, int(self.node[c]), code, p.describe_axis_error(code))
        return None

    def _write_frames(self, t: float, torques: np.ndarray, setup: bool) -> DriverError | None:
        if self._clear:
            for c in range(self.m):
                self._send_cmd(c, p.CLEAR_ERRORS, b"")
                self.axis_error[c] = 0
            self._clear = False
        if self._enable is not None:
            want = p.AxisState.CLOSED_LOOP_CONTROL if self._enable else p.AxisState.IDLE
            resend = t - self._enable_sent_at > 0.5  # lost on a lossy bus: sent again
            if self._enable != self._enable_sent or resend:
                for c in range(self.m):
                    if self._enable != self._enable_sent or self.axis_state[c] is not want:
                        self._send_cmd(c, p.SET_AXIS_STATE, p.U32_STRUCT.pack(want))
                self._enable_sent = self._enable
                self._enable_sent_at = t
        pack = p.TORQUE_STRUCT.pack_into
        for c in range(self.m):
            msg = self._torque_msg[c]
            pack(msg.data, 0, float(torques[c]))
            self._send(int(self.bus_of[c]), msg)
        return self._sends_failing()
