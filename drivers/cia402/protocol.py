"""CANopen (CiA 301) and drive profile (CiA 402) constants, frames and the power state machine.

Static PDO mapping used by cdprctl (documented in docs/drivers.md; a real drive is configured to
it with its own tool or by SDO):

* RPDO1 (0x200 + node), cyclic synchronous torque (mode 10), 4 bytes: controlword 0x6040
  (u16), target torque 0x6071 (i16, per-mille of the rated torque 0x6076).
* RPDO1, cyclic synchronous position (mode 8), 8 bytes: controlword 0x6040 (u16), target
  position 0x607A (i32, encoder counts), torque offset 0x60B2 (i16, per-mille). The drive
  interpolates the target linearly between SYNCs and closes its own position loop around it.
* TPDO1 (0x180 + node), 8 bytes, on every SYNC: statusword 0x6041 (u16), torque actual 0x6077
  (i16, per-mille), position actual 0x6064 (i32, encoder counts).
* TPDO2 (0x280 + node), 4 bytes, on every SYNC when enabled: velocity actual 0x606C (i32,
  counts/s).
"""

from __future__ import annotations

import enum
import struct

# -- COB-IDs (CiA 301 pre-defined connection set) ----------------------------------------------
NMT = 0x000
SYNC = 0x080
EMCY = 0x080  # + node
TPDO1 = 0x180  # + node
RPDO1 = 0x200  # + node
TPDO2 = 0x280  # + node
SDO_TX = 0x580  # + node: server → client
SDO_RX = 0x600  # + node: client → server
HEARTBEAT = 0x700  # + node

# NMT commands (CiA 301 §7.2.8.3.1)
NMT_START = 0x01
NMT_STOP = 0x02
NMT_PRE_OPERATIONAL = 0x80
NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82
# NMT states in heartbeats
HB_BOOTUP = 0x00
HB_STOPPED = 0x04
HB_OPERATIONAL = 0x05
HB_PRE_OPERATIONAL = 0x7F

# Objects
OD_DEVICE_TYPE = 0x1000  # bits 0-15: the device profile (402)
OD_ERROR_REGISTER = 0x1001
OD_ERROR_CODE = 0x603F
OD_MAX_TORQUE = 0x6072  # per mille of the rated torque
OD_SUPPORTED_DRIVE_MODES = 0x6502
OD_CONTROLWORD = 0x6040
OD_STATUSWORD = 0x6041
OD_MODES_OF_OPERATION = 0x6060
OD_MODES_DISPLAY = 0x6061
OD_POSITION_ACTUAL = 0x6064
OD_VELOCITY_ACTUAL = 0x606C
OD_TARGET_TORQUE = 0x6071
OD_RATED_TORQUE = 0x6076  # mN·m
OD_TORQUE_ACTUAL = 0x6077
OD_ABORT_CONNECTION = 0x6007  # what the drive does when the communication is lost
OD_PRODUCER_HEARTBEAT = 0x1017  # ms
# UNSIGNED8, CiA 301 §7.5.2.37: 0, the SYNC has no data; 2-240, it carries a counter that runs
# 1 … this value, so a drive knows when it missed one
OD_SYNC_COUNTER_OVERFLOW = 0x1019
SYNC_COUNTER_OVERFLOW = 240
OD_TARGET_POSITION = 0x607A
OD_TORQUE_OFFSET = 0x60B2
# position mode: how far (counts, UNSIGNED32; 0xFFFFFFFF: not monitored) and how long (ms,
# UNSIGNED16) the position actual may stay off the target before the drive faults (EMCY 0x8611)
# PDOs (CiA 301 §7.5.2.35-38): communication parameter (sub 1 COB-ID, bit 31 "not valid";
# sub 2 transmission type, 1: every SYNC) and mapping (sub 0 count, then entries index << 16 |
# sub << 8 | bits); the mappings cdprctl needs, by mode
RPDO1_COMM, RPDO1_MAP = 0x1400, 0x1600
TPDO1_COMM, TPDO1_MAP = 0x1800, 0x1A00
TPDO2_COMM, TPDO2_MAP = 0x1801, 0x1A01
PDO_NOT_VALID = 0x80000000
TRANSMISSION_EVERY_SYNC = 1
TPDO1_MAPPING = (0x60410010, 0x60770010, 0x60640020)  # statusword, torque, position actual
TPDO2_MAPPING = (0x606C0020,)  # velocity actual
OD_IDENTITY = 0x1018  # 1 vendor-ID, 2 product code, 3 revision, 4 serial number
OD_FOLLOWING_ERROR_WINDOW = 0x6065
OD_FOLLOWING_ERROR_TIMEOUT = 0x6066
FOLLOWING_ERROR_OFF = 0xFFFFFFFF
EMCY_FOLLOWING_ERROR = 0x8611
# Safe torque off (the drive's STO input open: the e-stop chain): no CiA code exists; each
# vendor has its own (docs/safety.md). The simulated drives report maxon EPOS4's.
EMCY_STO = 0x8A88
STO_CODES = {
    0x8A88: "safe torque off: the STO input is open (maxon EPOS4 'STO error')",
    0x5441: "disabled by the enable or STO input (Technosoft iPOS; Elmo: by INHIBIT or ABORT)",
    0xFF20: "safe torque off in use (Elmo Gold)",
}
MODE_CSP = 8  # cyclic synchronous position (CiA 402 §8)
MODE_CST = 10  # cyclic synchronous torque (CiA 402 §8)
#: the modes of operation cdprctl drives a CiA 402 drive in, by the ``[drives] mode`` name
MODES = {"cst": MODE_CST, "csp": MODE_CSP}
# 0x6502 (supported drive modes, CiA 402 §6.4.7): the bit of each mode cdprctl drives
SUPPORTED_MODE_BIT = {MODE_CSP: 7, MODE_CST: 9}
MODE_NAMES = {MODE_CSP: "cyclic synchronous position", MODE_CST: "cyclic synchronous torque"}
MODE_SHORT_NAMES = {MODE_CSP: "csp", MODE_CST: "cst"}  # as [drives] mode spells them

# CiA 301 §7.2.4.3.17 SDO abort codes: those the set-up tells apart, in words
SDO_ABORT_NO_OBJECT = 0x06020000
SDO_ABORT_NO_SUB = 0x06090011
SDO_ABORT_READ_ONLY = 0x06010002
SDO_ABORT_TEXT = {
    SDO_ABORT_NO_OBJECT: "the drive has no such object",
    SDO_ABORT_NO_SUB: "the drive has no such sub-index",
    SDO_ABORT_READ_ONLY: "read-only in this drive",
    0x06070010: "of another size in this drive",
    0x06090030: "value outside the drive's range",
    0x06090031: "value above the drive's range",
    0x06090032: "value below the drive's range",
    0x060A0023: "the drive holds no value",
    0x08000020: "the drive cannot store it now",
    0x08000022: "not in the drive's present state",
}
RPDO1_MAPPING = {  # by mode, what the cyclic codec (RPDO1_STRUCT, RPDO1_CSP_STRUCT) packs
    MODE_CST: (0x60400010, 0x60710010),  # controlword, target torque
    MODE_CSP: (0x60400010, 0x607A0020, 0x60B20010),  # controlword, target position, offset
}
ABORT_CONNECTION_QUICK_STOP = 3

# -- precompiled encoders/decoders of the cyclic path ------------------------------------------
RPDO1_STRUCT = struct.Struct("<Hh")  # controlword, target torque (per-mille)
RPDO1_CSP_STRUCT = struct.Struct("<Hih")  # controlword, target position, torque offset (pm)
TPDO1_STRUCT = struct.Struct("<Hhi")  # statusword, torque actual (per-mille), position (counts)
TPDO2_STRUCT = struct.Struct("<i")  # velocity actual (counts/s)
EMCY_STRUCT = struct.Struct("<HB5s")  # error code, error register, manufacturer data
SDO_STRUCT = struct.Struct("<BHB4s")  # command, index, subindex, data


class PowerState(enum.IntEnum):
    """CiA 402 §6.2 power states, decoded from the statusword."""

    NOT_READY_TO_SWITCH_ON = 0
    SWITCH_ON_DISABLED = 1
    READY_TO_SWITCH_ON = 2
    SWITCHED_ON = 3
    OPERATION_ENABLED = 4
    QUICK_STOP_ACTIVE = 5
    FAULT_REACTION_ACTIVE = 6
    FAULT = 7


# CiA 402 Table 30: (mask, value) of the statusword bits 0-3, 5, 6 in each state
STATUSWORD_STATES = (
    (0x4F, 0x00, PowerState.NOT_READY_TO_SWITCH_ON),
    (0x4F, 0x40, PowerState.SWITCH_ON_DISABLED),
    (0x6F, 0x21, PowerState.READY_TO_SWITCH_ON),
    (0x6F, 0x23, PowerState.SWITCHED_ON),
    (0x6F, 0x27, PowerState.OPERATION_ENABLED),
    (0x6F, 0x07, PowerState.QUICK_STOP_ACTIVE),
    (0x4F, 0x0F, PowerState.FAULT_REACTION_ACTIVE),
    (0x4F, 0x08, PowerState.FAULT),
)


def decode_statusword(sw: int) -> PowerState:
    """CiA 402 Table 30; a statusword of no state there reads as not ready (never enabled)."""
    for mask, value, state in STATUSWORD_STATES:
        if sw & mask == value:
            return state
    return PowerState.NOT_READY_TO_SWITCH_ON


STATUSWORD_OF = {  # what a drive reports in each state (bit 4 voltage enabled when powered)
    PowerState.NOT_READY_TO_SWITCH_ON: 0x0000,
    PowerState.SWITCH_ON_DISABLED: 0x0040,
    PowerState.READY_TO_SWITCH_ON: 0x0021,
    PowerState.SWITCHED_ON: 0x0033,
    PowerState.OPERATION_ENABLED: 0x0037,
    PowerState.QUICK_STOP_ACTIVE: 0x0017,
    PowerState.FAULT_REACTION_ACTIVE: 0x001F,
    PowerState.FAULT: 0x0008,
}


class Command(enum.IntEnum):
    """Controlword commands (CiA 402 Table 28) and the transitions they trigger."""

    SHUTDOWN = 0x0006  # transitions 2, 6, 8
    SWITCH_ON = 0x0007  # transition 3 (and 5: disable operation)
    ENABLE_OPERATION = 0x000F  # transitions 4, 16 (3+4 from READY_TO_SWITCH_ON)
    DISABLE_VOLTAGE = 0x0000  # transitions 7, 9, 10, 12
    QUICK_STOP = 0x0002  # transitions 7, 10, 11
    FAULT_RESET = 0x0080  # transition 15, on the rising edge of bit 7


# The controller's side of the state machine: the controlword to send, per state, to move
# towards ENABLED (transitions 2 → 3 → 4) or DISABLED (7, 9, 10, 12).
TOWARDS_ENABLED: dict[PowerState, Command] = {
    PowerState.NOT_READY_TO_SWITCH_ON: Command.DISABLE_VOLTAGE,  # transition 1 is automatic
    PowerState.SWITCH_ON_DISABLED: Command.SHUTDOWN,  # 2
    PowerState.READY_TO_SWITCH_ON: Command.SWITCH_ON,  # 3
    PowerState.SWITCHED_ON: Command.ENABLE_OPERATION,  # 4
    PowerState.OPERATION_ENABLED: Command.ENABLE_OPERATION,  # stay
    PowerState.QUICK_STOP_ACTIVE: Command.DISABLE_VOLTAGE,  # 12, then 2 → 3 → 4
    PowerState.FAULT_REACTION_ACTIVE: Command.DISABLE_VOLTAGE,  # 14 is automatic
    PowerState.FAULT: Command.DISABLE_VOLTAGE,  # 15 only on a fault-reset request
}

# Drive side (the simulator's drives): (state, command) → next state, with the transition
# number of CiA 402 Figure 14.
TRANSITIONS: dict[tuple[PowerState, Command], tuple[PowerState, int]] = {
    (PowerState.SWITCH_ON_DISABLED, Command.SHUTDOWN): (PowerState.READY_TO_SWITCH_ON, 2),
    (PowerState.READY_TO_SWITCH_ON, Command.SWITCH_ON): (PowerState.SWITCHED_ON, 3),
    (PowerState.READY_TO_SWITCH_ON, Command.ENABLE_OPERATION): (PowerState.SWITCHED_ON, 3),
    (PowerState.SWITCHED_ON, Command.ENABLE_OPERATION): (PowerState.OPERATION_ENABLED, 4),
    (PowerState.OPERATION_ENABLED, Command.SWITCH_ON): (PowerState.SWITCHED_ON, 5),
    (PowerState.SWITCHED_ON, Command.SHUTDOWN): (PowerState.READY_TO_SWITCH_ON, 6),
    (PowerState.READY_TO_SWITCH_ON, Command.DISABLE_VOLTAGE): (PowerState.SWITCH_ON_DISABLED, 7),
    (PowerState.READY_TO_SWITCH_ON, Command.QUICK_STOP): (PowerState.SWITCH_ON_DISABLED, 7),
    (PowerState.OPERATION_ENABLED, Command.SHUTDOWN): (PowerState.READY_TO_SWITCH_ON, 8),
    (PowerState.OPERATION_ENABLED, Command.DISABLE_VOLTAGE): (PowerState.SWITCH_ON_DISABLED, 9),
    (PowerState.SWITCHED_ON, Command.DISABLE_VOLTAGE): (PowerState.SWITCH_ON_DISABLED, 10),
    (PowerState.SWITCHED_ON, Command.QUICK_STOP): (PowerState.SWITCH_ON_DISABLED, 10),
    (PowerState.OPERATION_ENABLED, Command.QUICK_STOP): (PowerState.QUICK_STOP_ACTIVE, 11),
    (PowerState.QUICK_STOP_ACTIVE, Command.DISABLE_VOLTAGE): (PowerState.SWITCH_ON_DISABLED, 12),
    (PowerState.QUICK_STOP_ACTIVE, Command.ENABLE_OPERATION): (PowerState.OPERATION_ENABLED, 16),
    (PowerState.FAULT, Command.FAULT_RESET): (PowerState.SWITCH_ON_DISABLED, 15),
}


def command_of(controlword: int) -> Command | None:
    """The command a controlword encodes (CiA 402 Table 28), fault reset first."""
    if controlword & 0x80:
        return Command.FAULT_RESET
    cw = controlword & 0x0F
    if cw & 0x02 == 0:
        return Command.DISABLE_VOLTAGE
    if cw & 0x06 == 0x02:
        return Command.QUICK_STOP
    if cw == 0x06 or cw == 0x0E:
        return Command.SHUTDOWN
    if cw == 0x07:
        return Command.SWITCH_ON
    if cw == 0x0F:
        return Command.ENABLE_OPERATION
    return None


# -- EMCY error codes (CiA 301 Table 21, CiA 402 Table 2) --------------------------------------
EMCY_CODES = {
    0x0000: "error reset or no error",
    0x1000: "generic error",
    0x2310: "continuous over-current",
    0x2320: "short circuit at the outputs",
    0x3210: "DC link over-voltage",
    0x3220: "DC link under-voltage",
    0x4210: "excess temperature, device",
    0x4310: "excess temperature, drive",
    0x5530: "EEPROM / data storage",
    0x6100: "internal software",
    0x7121: "motor blocked",
    0x7300: "sensor (encoder) fault",
    0x7305: "incremental sensor 1 fault",
    0x8110: "CAN overrun (objects lost)",
    0x8120: "CAN in error passive mode",
    0x8130: "life guard or heartbeat error",
    0x8140: "recovered from bus off",
    0x8611: "following error",
    0x8612: "reference limit",
    0x9000: "external error",
}  # the device-specific codes (0xFFxx) are described by their class
# (value, mask, class) of CiA 301 Table 21: the first digit, or the first two where the table
# names them (0x5, 0x7, 0x9: xx00 only; 0xF0 additional functions, 0xFF device specific)
EMCY_CLASSES = (
    (0x1000, 0xFF00, "generic"),
    (0x2000, 0xF000, "current"),
    (0x3000, 0xF000, "voltage"),
    (0x4000, 0xF000, "temperature"),
    (0x5000, 0xFF00, "device hardware"),
    (0x6000, 0xF000, "device software"),
    (0x7000, 0xFF00, "additional modules"),
    (0x8000, 0xF000, "monitoring / communication"),
    (0x9000, 0xFF00, "external"),
    (0xF000, 0xFF00, "additional functions"),
    (0xFF00, 0xFF00, "device specific"),
)


def describe_emcy(code: int) -> str:
    if code in EMCY_CODES:
        return EMCY_CODES[code]
    if code in STO_CODES:
        return STO_CODES[code]
    cls = next((name for value, mask, name in EMCY_CLASSES if code & mask == value),
               "unknown class")  # fmt: skip
    return f"{cls} error (code 0x{code:04X})"


def sdo_download(index: int, subindex: int, value: int, size: int) -> bytes:
    """Expedited SDO download request (CiA 301 §7.2.4.3.3): ``size`` bytes of ``value``."""
    cmd = {1: 0x2F, 2: 0x2B, 3: 0x27, 4: 0x23}[size]
    data = (value & ((1 << (8 * size)) - 1)).to_bytes(size, "little")
    return SDO_STRUCT.pack(cmd, index, subindex, data)  # "4s" pads the unused bytes with 0


def sdo_upload(index: int, subindex: int) -> bytes:
    return SDO_STRUCT.pack(0x40, index, subindex, b"\0\0\0\0")
