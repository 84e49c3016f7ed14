"""ODrive axes over CAN Simple, in position or torque mode, sharing everything above the
protocol.

Set-up sends Set_Controller_Mode (position or torque, passthrough input) and, in position mode
(``[drives] mode = "csp"``), the cascaded loops' gains and the limits from the model
(``gains.py``: Set_Pos_Gain, Set_Vel_Gains, Set_Limits; CAN Simple has no message that reads
them back); enabling is Set_Axis_State CLOSED_LOOP_CONTROL, disabling IDLE, fault reset
Clear_Errors. The axes stream their heartbeat and encoder estimates cyclically (configured on
the ODrive), and their torques in torque mode. The cyclic ``write`` sends each axis
Set_Input_Pos (the target, its rate as velocity feed-forward, the torque as torque
feed-forward) in position mode, its Get_Torques asked for by RTR just before (the torque at the
end of the setpoint it held: ``cyclic.pack_frames_kernel``), or Set_Input_Torque (a gripper's
cable, or torque mode). An ODrive does not supervise its following error: the driver does, as
a CiA 402 drive would (0x8611, ``_following``).
"""

from __future__ import annotations

import math
from typing import Any

import can
import numpy as np

from cdprctl.core.numerics import add_count
from drivers import blocking
from drivers.base import WinchDriver
from drivers.errors import DriveFaultError, DriverError, following_error_text
from drivers.odrive import protocol as p
from drivers.odrive.cyclic import following_kernel, pack_frames_kernel
from drivers.odrive.gains import AxisGains, axis_gains
from drivers.registry import register_driver
from drivers.transport import CanTransport
from drivers.vocabulary import CLAMPED_COMMANDS, DriveState

TWO_PI = 2.0 * math.pi
FE = 0x8611  # CiA 402's code for a following error, the same fault for the same rule
FE_BY = "checked by cdprctl: the ODrive does not"
# enum members looked up once: each lookup of a member took a block (Python 3.11)
_CLOSED_LOOP, _IDLE = p.AxisState.CLOSED_LOOP_CONTROL, p.AxisState.IDLE
_ENABLED, _DISABLED = DriveState.ENABLED, DriveState.DISABLED
_FAULT, _UNKNOWN = DriveState.FAULT, DriveState.UNKNOWN
# a heartbeat's axis state byte → AxisState (UNDEFINED for a value the enum lacks)
_AXIS_STATE_OF = [p.AxisState.UNDEFINED] * 256
for _s in p.AxisState:
    _AXIS_STATE_OF[_s.value] = _s


@register_driver
class ODriveDriver(WinchDriver):
    name = "odrive"
    drive_label = "ODrive axis"
    feedback_label = "encoder estimate"
    transport: CanTransport

    def __init__(self, model: Any, **kwargs: Any):
        super().__init__(model, **kwargs)
        m = self.m
        self.transport = t = CanTransport(m, self.config, self.bus_overrides, self.stats,
                                          lambda: self.clock())  # fmt: skip
        self.buses, self.media, self.node, self.bus_of = t.buses, t.media, t.node, t.bus_of
        self._send = t.send  # an attribute: one call a frame (a test may wrap it)
        for c in range(m):
            b, n = int(self.bus_of[c]), int(self.node[c])
            for cmd in (p.HEARTBEAT, p.GET_ENCODER_ESTIMATES, p.GET_TORQUES):
                t.dispatch[(b, p.arbitration_id(n, cmd))] = (cmd, c)
        drives = self.config
        # per cable: its axis holds a position (csp; a gripper's cable stays in torque mode)
        self.csp = [drives.mode_of(c) == "csp" for c in range(m)]
        self.gains: list[AxisGains | None] = [
            axis_gains(model, c, self.period) if self.csp[c] else None for c in range(m)
        ]
        self._cyclic_msg = [
            can.Message(
                arbitration_id=p.arbitration_id(
                    int(self.node[c]), p.SET_INPUT_POS if self.csp[c] else p.SET_INPUT_TORQUE
                ),
                data=bytearray(8 if self.csp[c] else 4),
                is_extended_id=False,
            )
            for c in range(m)
        ]
        # Get_Torques asked for by RTR before each Set_Input_Pos (position mode)
        self._torque_request = [
            can.Message(
                arbitration_id=p.arbitration_id(int(self.node[c]), p.GET_TORQUES),
                is_remote_frame=True, dlc=8, is_extended_id=False,
            )
            for c in range(m)
        ]  # fmt: skip
        self._sent_target = np.zeros(m)  # rad: the last position target each axis was given
        # rad: the targets before the last one and before that: the path of the last two
        # holds, from where the following error is measured; the hold before the last one
        # (the one the last torque asked for ended) held their middle, ``cyclic.pack_frames_kernel``
        self._hold_from = np.zeros(m)
        self._path_from = np.zeros(m)
        # N·m/rad: the share of the loop's stiffness that hold's pull adds to that torque
        self._pull_gain = np.array([g.ripple * g.kp if g else 0.0 for g in self.gains])
        # the following error's supervision (rad, s): the window and time-out of CiA 402
        # 0x6065/0x6066, as [drives] sets them; how long each axis has been beyond it
        self.following_window = np.array([
            drives.following_error_window_rad(w.winch, g.kp if g else None)
            for w, g in zip(model.cables, self.gains, strict=True)
        ])  # fmt: skip
        self._beyond = np.zeros(m)
        self._following_off = np.zeros(m)  # rad: how far off each axis was when it latched
        self._m_per_rad = np.array([w.winch.drum_radius / w.winch.gear_ratio
                                    for w in model.cables])  # fmt: skip
        self._checked_at = math.nan
        self.following = np.zeros(m, dtype=np.bool_)  # latched until a fault reset
        self.axis_state = [p.AxisState.UNDEFINED] * m
        self.axis_error = np.zeros(m, dtype=np.int64)
        self._enable: bool | None = None
        self._enable_sent: bool | None = None
        self._enable_sent_at = -math.inf
        self._clear = False
        self._t = 0.0  # s, the read under way (its frames, _frame)
        self._on_frame = self._frame  # bound once: a bound method per read was a block
        # the cyclic path's arrays (cyclic.py): the modes and closed-loop states as flags,
        # each cyclic frame's bytes, a float32 and its bytes to pack through
        self._csp = np.array(self.csp, dtype=np.bool_)
        self._closed = np.zeros(m, dtype=np.bool_)
        self._bus_of_list = [int(b) for b in self.bus_of]
        self._frame_bytes = tuple(np.frombuffer(msg.data, dtype=np.uint8)
                                  for msg in self._cyclic_msg)  # fmt: skip
        self._f32 = np.zeros(1, dtype=np.float32)
        self._f32_bytes = self._f32.view(np.uint8)

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
            g = self.gains[c]
            mode = p.CONTROL_MODE_TORQUE if g is None else p.CONTROL_MODE_POSITION
            self._send_cmd(
                c, p.SET_CONTROLLER_MODE, p.MODE_STRUCT.pack(mode, p.INPUT_MODE_PASSTHROUGH)
            )
            if g is not None:
                self._send_cmd(c, p.SET_POS_GAIN, p.TORQUE_STRUCT.pack(g.pos_gain))
                pair = p.FLOAT_PAIR_STRUCT.pack
                self._send_cmd(c, p.SET_VEL_GAINS, pair(g.vel_gain, g.vel_integrator_gain))
                self._send_cmd(c, p.SET_LIMITS, pair(g.vel_limit, g.current_limit))
            self._send_cmd(c, p.SET_AXIS_STATE, p.U32_STRUCT.pack(p.AxisState.IDLE))
        lv = self.liveness
        lv.started = True
        blocking.await_first_feedback(
            self,
            timeout,
            lambda: bool(np.all(np.isfinite(lv.fb_stamp)) and np.all(np.isfinite(lv.last_hb))),
            "encoder estimates (ODrive axes)",
        )
        for a in (self._sent_target, self._hold_from, self._path_from):
            a[:] = self.states.position

    def _request_enable(self, enable: bool) -> None:
        self._enable = enable

    def _fault_reset(self) -> None:
        self._clear = True
        self.following[:] = False
        self._beyond[:] = 0.0

    def _drain(self, t: float) -> None:
        self._t = t
        self.transport.receive(self._on_frame)

    def _frame(self, cmd: int, c: int, data: Any) -> None:
        """One frame of axis ``c``."""
        t = self._t
        if cmd == p.GET_ENCODER_ESTIMATES and len(data) == 8:
            pos, vel = p.ENCODER_STRUCT.unpack(data)
            step = pos * TWO_PI - self.states.position.item(c)  # item: a float, not a scalar
            if not (math.isfinite(pos) and math.isfinite(vel)) or not self.liveness.plausible(
                c, step, t
            ):
                return  # a corrupted frame: dropped whole, like a lost one
            self.states.position[c] = pos * TWO_PI
            self.states.velocity[c] = vel * TWO_PI
            self.liveness.fresh[c] = True
            self.liveness.fb_stamp[c] = t
        elif cmd == p.GET_TORQUES and len(data) == 8:
            tau = p.TORQUES_STRUCT.unpack(data)[1]
            if self.csp[c]:
                # asked for as the next setpoint went out: the estimate closes the period
                # the axis held the middle of the last two targets (``cyclic.pack_frames_kernel``),
                # where a drive interpolating between them stands at the last target;
                # the part of the loop's pull kp (setpoint − target) that accelerates the
                # rotor within the staircase, not the cable, taken out (``hold_ripple``):
                # rowc's demo 0.47 → 0.011 mm RMS (lock-step, 250 Hz)
                # setpoint − target
                pull = 0.5 * (self._path_from.item(c) - self._hold_from.item(c))
                tau -= self._pull_gain.item(c) * pull
            self.states.torque[c] = tau
        elif cmd == p.HEARTBEAT and len(data) >= 7:
            # HEARTBEAT_STRUCT's first two fields, read in place (no padded copy, no tuple)
            self.axis_error[c] = p.U32_STRUCT.unpack_from(data, 0)[0]
            state = _AXIS_STATE_OF[data[4]]  # a table: the enum's call took blocks
            self.axis_state[c] = state
            self._closed[c] = state is _CLOSED_LOOP
            self.liveness.last_hb[c] = t
        else:
            self.stats.frames_ignored += 1

    def _update_states(self) -> bool:
        """Each axis's state from its heartbeat (``_cable_fault``, cable by cable)."""
        self._following(self.states.stamp)
        fault, c = False, 0
        while c < self.m:  # every cable's state set: no early exit
            if self._cable_fault(c) is not None:
                fault = True
            c += 1
        return fault

    def _following(self, t: float) -> None:
        """Each enabled axis in position mode off its path by more than the window: for
        longer than the time-out, latched as a following-error fault (``FE``). The ODrive has
        no such supervision of its own; the read after a write measures it, so its resolution
        is the control period (two reads beyond the window at 250 Hz). The path is the one an
        interpolating drive would have followed over the last two holds: the encoder estimate
        comes on the ODrive's own timer, from either hold and anywhere in it, and the setpoint
        held is half a period ahead of the path by design (``cyclic.pack_frames_kernel``); measured
        against the setpoint, rowc's 1.6 mm window at 0.3 m/s tripped in real time."""
        dt = t - self._checked_at if math.isfinite(self._checked_at) else 0.0
        self._checked_at = t
        following_kernel(
            self._csp, self._closed, self._path_from, self._hold_from, self._sent_target,
            self.states.position, self.following_window, self._beyond, self.following,
            self._following_off, dt, self.config.following_error_timeout,
        )  # fmt: skip

    def _cable_fault(self, c: int) -> DriverError | None:
        st = self.states
        code = self.axis_error.item(c)  # item: an int, not a numpy scalar
        st.fault_code[c] = code
        if self.following[c]:
            st.state[c] = DriveState.FAULT
            st.fault_code[c] = FE
            return DriveFaultError(c, int(self.node[c]), FE, following_error_text(
                float(self._following_off[c]), float(self.following_window[c]),
                float(self._m_per_rad[c]), self.config.following_error_timeout, FE_BY))
        if code:
            st.state[c] = _FAULT
        elif self.axis_state[c] is _CLOSED_LOOP:
            st.state[c] = _ENABLED
        elif self.axis_state[c] is _IDLE:
            st.state[c] = _DISABLED
        else:
            st.state[c] = _UNKNOWN
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
            want = _CLOSED_LOOP if self._enable else _IDLE
            resend = t - self._enable_sent_at > 0.5  # lost on a lossy bus: sent again
            if self._enable != self._enable_sent or resend:
                c = 0
                while c < self.m:  # by index: checked every 0.5 s, mostly sending nothing
                    if self._enable != self._enable_sent or self.axis_state[c] is not want:
                        self._send_cmd(c, p.SET_AXIS_STATE, p.U32_STRUCT.pack(want))
                    c += 1
                self._enable_sent = self._enable
                self._enable_sent_at = t
        clamped = pack_frames_kernel(
            self.targets, torques, self._csp, self.period, self._sent_target, self._hold_from,
            self._path_from, self._frame_bytes, self._f32, self._f32_bytes,
        )  # fmt: skip
        if clamped:
            add_count(self.stats.counts, CLAMPED_COMMANDS, clamped)
        send, bus_of, csp, c = self._send, self._bus_of_list, self.csp, 0
        while c < self.m:  # by index: a for loop's iterator was a block
            if csp[c]:  # Get_Torques asked for as the setpoint goes out (_frame)
                send(bus_of[c], self._torque_request[c])
            send(bus_of[c], self._cyclic_msg[c])
            c += 1
        return self.transport.sends_failing()

    # Set_Input_Pos (cyclic.pack_frames_kernel) for the period to come: the target's rate over
    # the last period as the velocity feed-forward, the torque as the torque feed-forward
    # (each int16 field saturated; a saturated rate counts as a clamped command) and as the
    # position the middle of the last target and this one. A CiA 402 drive interpolates from
    # the one to the other over the period; an ODrive in passthrough holds what it was sent,
    # its position loop pulling against the feed-forward: held at the new target the motor
    # led the interpolated path by half a period on average (rowc's demo: 1 mm RMS of
    # tracking, lock-step), held at the middle the pull averages out.
