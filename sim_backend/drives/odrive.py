"""An ODrive axis (CAN Simple) as the simulator's CAN node.

Answers Set_Controller_Mode (torque or position control; passthrough input), Set_Axis_State
(IDLE: brake; CLOSED_LOOP_CONTROL: the loop on), Set_Input_Torque and Set_Input_Pos (applied
at once: the protocol has no SYNC, and passthrough neither filters nor interpolates),
Set_Pos_Gain, Set_Vel_Gains, Set_Limits, Clear_Errors, Estop; streams heartbeat and encoder
estimates at every simulation step it is ticked, and its torques in torque control (the cyclic
messages an ODrive is configured to send: docs/drivers.md), and answers an RTR for encoder
estimates or torques with them (in position control the driver asks for the torques before
each setpoint); the watchdog (comm timeout) drops the axis to IDLE with the watchdog
error bit. In position control the firmware's cascade runs at every physics step
(``servo._cascade_torque``); entering closed loop it takes the position where the motor
stands as its input and clears its integrator (firmware ``Axis::run_closed_loop_control_loop``),
and a speed beyond ``vel_limit_tolerance`` × ``vel_limit`` is its overspeed error.
"""

from __future__ import annotations

import math

import can

from drivers.odrive import protocol as p
from sim_backend.plant import CdprPlant

WATCHDOG_EXPIRED = 0x01000000
VELOCITY_LIMIT_VIOLATION = 0x00008000  # the overspeed error
ESTOP_REQUESTED = 0x02000000
HEARTBEAT_PERIOD = 0.1  # s
VEL_LIMIT_TOLERANCE = 1.2  # the firmware's default controller.config.vel_limit_tolerance
TWO_PI = 2.0 * math.pi


class ODriveAxis:
    def __init__(
        self,
        node_id: int,
        cable: int,
        plant: CdprPlant,
        torque_limit: float,
        comm_timeout: float,
        torque_constant: float | None = None,
    ):
        """``torque_limit`` (N·m): what the motor can give; ``torque_constant`` (N·m/A, the
        ODrive's motor.config.torque_constant): Set_Limits' current limit times it lowers the
        torque limit (None: Set_Limits' current is not applied)."""
        self.node_id = node_id
        self.cable = cable
        self.plant = plant
        self.torque_limit = torque_limit
        self.max_torque = torque_limit
        self.torque_constant = torque_constant
        self.comm_timeout = comm_timeout
        self.state = p.AxisState.IDLE
        self.control_mode = 0
        self.error = 0
        self.torque_cmd = 0.0
        # position control: the inputs (turns, turn/s, N·m) and the gains and limits as the
        # axis was sent them (its firmware's defaults until then: pos_gain 20, vel_gain
        # 0.16, vel_integrator_gain 0.32, vel_limit 2 turn/s)
        self.input_pos = 0.0
        self.input_vel = 0.0
        self.pos_gain = 20.0
        self.vel_gain = 0.16
        self.vel_integrator_gain = 0.32
        self.vel_limit = 2.0
        self.last_rx = -math.inf
        self.last_hb = -math.inf
        self.silent = False
        self.encoder_offset = 0.0  # rad, fault injection

    def _msg(self, cmd: int, data: bytes) -> can.Message:
        return can.Message(
            arbitration_id=p.arbitration_id(self.node_id, cmd), data=data, is_extended_id=False
        )

    def on_frame(self, cmd: int, data: bytes, remote: bool, t: float) -> list[can.Message]:
        if remote:  # a request: answered from where the axis is, before any later frame
            if cmd == p.GET_TORQUES and not self.silent:
                return [self._torques()]
            if cmd == p.GET_ENCODER_ESTIMATES and not self.silent:
                return [self._estimates()]
            return []
        self.last_rx = t
        if cmd == p.SET_INPUT_TORQUE and len(data) >= 4:
            self.torque_cmd = p.TORQUE_STRUCT.unpack(data[:4])[0]
        elif cmd == p.SET_INPUT_POS and len(data) >= 8:
            pos, vel, tau = p.INPUT_POS_STRUCT.unpack(data[:8])
            self.input_pos = pos
            self.input_vel = vel * p.VEL_FF_SCALE
            self.torque_cmd = tau * p.TORQUE_FF_SCALE
        elif cmd == p.SET_AXIS_STATE and len(data) >= 4:
            want = p.U32_STRUCT.unpack(data[:4])[0]
            if (
                want == p.AxisState.CLOSED_LOOP_CONTROL
                and self.error == 0
                and self.control_mode in (p.CONTROL_MODE_TORQUE, p.CONTROL_MODE_POSITION)
            ):
                if self.state is not p.AxisState.CLOSED_LOOP_CONTROL:
                    self._enter_closed_loop()
                self.state = p.AxisState.CLOSED_LOOP_CONTROL
            elif want == p.AxisState.IDLE:
                self.state = p.AxisState.IDLE
        elif cmd == p.SET_CONTROLLER_MODE and len(data) >= 8:
            self.control_mode = p.MODE_STRUCT.unpack(data[:8])[0]
        elif cmd == p.SET_POS_GAIN and len(data) >= 4:
            self.pos_gain = p.TORQUE_STRUCT.unpack(data[:4])[0]
        elif cmd == p.SET_VEL_GAINS and len(data) >= 8:
            self.vel_gain, self.vel_integrator_gain = p.FLOAT_PAIR_STRUCT.unpack(data[:8])
        elif cmd == p.SET_LIMITS and len(data) >= 8:
            self.vel_limit, current = p.FLOAT_PAIR_STRUCT.unpack(data[:8])
            if self.torque_constant is not None:
                self.torque_limit = min(self.max_torque, current * self.torque_constant)
        elif cmd == p.CLEAR_ERRORS:
            self.error = 0
        elif cmd == p.ESTOP:
            self.inject_fault(ESTOP_REQUESTED)
        self._apply()
        return []

    def _enter_closed_loop(self) -> None:
        """The firmware's start of closed loop: the input position where the motor stands,
        the velocity integrator cleared."""
        self.input_pos = self.position_turns()
        self.plant.servo.integral[self.cable] = 0.0

    def position_turns(self) -> float:
        """The encoder estimate (turns of the motor)."""
        return (self.plant.theta[self.cable] + self.encoder_offset) / TWO_PI

    def _apply(self) -> None:
        c, servo = self.cable, self.plant.servo
        on = self.state is p.AxisState.CLOSED_LOOP_CONTROL and self.error == 0
        if on and self.control_mode == p.CONTROL_MODE_POSITION:
            servo.kp[c] = 1.0  # the loop on; the cascade's gains are the ones below
            servo.pos_gain[c] = self.pos_gain
            servo.kd[c] = self.vel_gain / TWO_PI  # N·m·s/rad
            servo.vel_ki[c] = self.vel_integrator_gain / TWO_PI  # N·m/rad
            servo.vel_limit[c] = self.vel_limit * TWO_PI  # rad/s
            servo.limit[c] = self.torque_limit
            servo.target[c] = self.input_pos * TWO_PI - self.encoder_offset
            servo.rate[c] = self.input_vel * TWO_PI
            self.plant.motor_torque[c] = self.torque_cmd  # the torque feed-forward
            self.plant.brake[c] = False
            return
        servo.kp[c] = servo.pos_gain[c] = 0.0
        if on:
            self.plant.motor_torque[c] = max(
                -self.torque_limit, min(self.torque_limit, self.torque_cmd)
            )
            self.plant.brake[c] = False
        else:
            self.plant.motor_torque[c] = 0.0
            self.plant.close_brake(c)

    def tick(self, t: float) -> list[can.Message]:
        closed = self.state is p.AxisState.CLOSED_LOOP_CONTROL
        if closed and t - self.last_rx > self.comm_timeout:
            self.inject_fault(WATCHDOG_EXPIRED)
        vel = self.plant.theta_dot[self.cable] / TWO_PI
        position = self.control_mode == p.CONTROL_MODE_POSITION
        if closed and position and abs(vel) > VEL_LIMIT_TOLERANCE * self.vel_limit:
            self.inject_fault(VELOCITY_LIMIT_VIOLATION)
        self._apply()
        if self.silent:
            return []
        out = [self._estimates()]
        if not position:
            out.append(self._torques())
        if t - self.last_hb >= HEARTBEAT_PERIOD - 1e-9:
            out.append(
                self._msg(p.HEARTBEAT, p.HEARTBEAT_STRUCT.pack(self.error, int(self.state), 0, 1))
            )
            self.last_hb = t
        return out

    def _estimates(self) -> can.Message:
        """Get_Encoder_Estimates: turns and turn/s of the motor."""
        vel = self.plant.theta_dot[self.cable] / TWO_PI
        return self._msg(p.GET_ENCODER_ESTIMATES, p.ENCODER_STRUCT.pack(self.position_turns(), vel))

    def _torques(self) -> can.Message:
        """Get_Torques: the torque asked for and the one applied in the last loop step (N·m;
        the firmware's step is 125 µs, the physics step here 200 µs)."""
        c = self.cable
        csp = self.plant.servo.kp[c] > 0.0
        applied = self.plant.servo.applied[c] if csp else self.plant.motor_torque[c]
        return self._msg(p.GET_TORQUES, p.TORQUES_STRUCT.pack(self.torque_cmd, applied))

    def inject_fault(self, code: int) -> can.Message:
        self.error |= code
        self.state = p.AxisState.IDLE
        self._apply()
        return self._msg(p.HEARTBEAT, p.HEARTBEAT_STRUCT.pack(self.error, int(self.state), 0, 0))
