"""ODrive "CAN Simple" protocol (ODrive firmware 0.5/0.6): 11-bit ids ``node_id << 5 | cmd_id``,
little-endian payloads. Positions in turns and velocities in turns/s of the motor, torques in
N·m (docs.odriverobotics.com, "CAN Protocol")."""

from __future__ import annotations

import enum
import struct

HEARTBEAT = 0x01  # axis_error u32, axis_state u8, procedure_result u8, trajectory_done u8
ESTOP = 0x02
SET_AXIS_STATE = 0x07  # u32
GET_ENCODER_ESTIMATES = 0x09  # pos f32 (turns), vel f32 (turns/s)
SET_CONTROLLER_MODE = 0x0B  # control_mode u32, input_mode u32
# input position f32 (turns), velocity feed-forward i16 (0.001 turn/s), torque feed-forward
# i16 (0.001 N·m)
SET_INPUT_POS = 0x0C
SET_INPUT_TORQUE = 0x0E  # f32 N·m
SET_LIMITS = 0x0F  # velocity limit f32 (turns/s), current limit f32 (A)
CLEAR_ERRORS = 0x18
SET_POS_GAIN = 0x1A  # f32 (turns/s)/turn
SET_VEL_GAINS = 0x1B  # velocity gain f32 N·m/(turn/s), velocity integrator gain f32 N·m/turn
GET_TORQUES = 0x1C  # torque_target f32, torque_estimate f32


class AxisState(enum.IntEnum):
    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8


CONTROL_MODE_TORQUE = 1
CONTROL_MODE_POSITION = 3
INPUT_MODE_PASSTHROUGH = 1
# Set_Input_Pos's feed-forward scales: what one count of its int16 fields stands for
VEL_FF_SCALE = 0.001  # turn/s
TORQUE_FF_SCALE = 0.001  # N·m
INT16_MAX = 32767

AXIS_ERRORS = {  # ODrive 0.6 ODriveError bits (subset)
    0x00000001: "initializing",
    0x00000002: "system level",
    0x00000004: "timing error",
    0x00000008: "missing estimate",
    0x00000010: "bad config",
    0x00000020: "DRV fault",
    0x00000040: "missing input",
    0x00000100: "DC bus over-voltage",
    0x00000200: "DC bus under-voltage",
    0x00000400: "DC bus over-current",
    0x00000800: "DC bus over-regen current",
    0x00001000: "current limit violation",
    0x00002000: "motor over-temperature",
    0x00004000: "inverter over-temperature",
    0x00008000: "velocity limit violation",
    0x00010000: "position limit violation",
    0x01000000: "watchdog timer expired",
    0x02000000: "estop requested",
    0x04000000: "spinout detected",
    0x08000000: "brake resistor disarmed",
    0x10000000: "thermistor disconnected",
    0x40000000: "calibration error",
}

HEARTBEAT_STRUCT = struct.Struct("<IBBBx")
ENCODER_STRUCT = struct.Struct("<ff")
TORQUES_STRUCT = struct.Struct("<ff")
TORQUE_STRUCT = struct.Struct("<f")
U32_STRUCT = struct.Struct("<I")
MODE_STRUCT = struct.Struct("<II")
INPUT_POS_STRUCT = struct.Struct("<fhh")
FLOAT_PAIR_STRUCT = struct.Struct("<ff")  # Set_Limits, Set_Vel_Gains


def arbitration_id(node: int, cmd: int) -> int:
    return (node << 5) | cmd


def describe_axis_error(code: int) -> str:
    names = [text for bit, text in AXIS_ERRORS.items() if code & bit]
    return ", ".join(names) if names else f"error bits 0x{code:08X}"
