"""The set-up of one CiA 402 drive, by SDO in PRE-OPERATIONAL, at every start: identity,
rated torque against the config, the PDO mapping the cyclic codec needs (``pdo_setup``), the
mode after 0x6502, heartbeat, abort-connection option, torque limit, SYNC counter and, in
position mode, the following error; a DCF's ParameterValues first (cdprctl's own settings
win). Outside the loop; raises DriverInitializationError naming the drive and the object."""

from __future__ import annotations

from typing import Any

from drivers.cia402 import pdo_setup
from drivers.cia402 import protocol as p
from drivers.cia402.dcf import parameter_values
from drivers.cia402.sdo_client import SdoClient, identity, optional
from drivers.errors import DriverInitializationError, SdoAbortError


def configure_drive(drv: Any, sdo: SdoClient, c: int, timeout: float) -> None:
    """Identity (0x1018, logged), rated torque (0x6076) against the config, the PDOs the
    codec needs (``pdo_setup``), mode (0x6502 first), heartbeat, abort-connection option,
    torque limit (0x6072), SYNC counter and, in position mode, the following error."""
    n = int(drv.node[c])
    who = f"drive of cable index {c} (node {n})"
    mode = drv.modes[c]

    def read(index: int, sub: int) -> int:
        return sdo.read(c, index, sub, timeout, signed=False)

    def write(index: int, sub: int, value: int, size: int) -> None:
        sdo.write(c, index, sub, value, size, timeout)

    drv.identities[c] = identity(read)
    # Five heartbeats per timeout: with three (167 ms of 0.5 s) the loop's 4 ms ticks left
    # two in some windows, and two lost frames in a row at 5 % loss stopped the robot as
    # a lost drive (lock-step reliability matrix, 1 of 3 seeds); five is 10 Hz, the rate
    # the bus-load budget counts
    hb_ms = max(1, round(drv.config.heartbeat_timeout * 1000 / 5))
    # before a DCF can write it
    drv._reset_flags[c] = optional(read, p.OD_PRODUCER_HEARTBEAT) != hb_ms
    dcf = drv._dcf[c]
    if dcf:  # the integrator's parameters first; cdprctl's own settings below win
        for index, sub, value, size in parameter_values(dcf, n):
            try:
                write(index, sub, value, size)
            except SdoAbortError as exc:
                raise DriverInitializationError(
                    f"{who}: refused 0x{index:04X}:{sub:02X} := {value} from {dcf} "
                    f"(SDO abort 0x{exc.code:08X})"
                ) from exc
    rated = optional(read, p.OD_RATED_TORQUE)
    if rated is not None and abs(rated / 1000.0 - drv.rated_torque) > 0.01 * drv.rated_torque:
        raise DriverInitializationError(
            f"{who}: rated torque 0x6076 is {rated} mN·m, the config says "
            f"{drv.rated_torque * 1000:.0f} mN·m ([drives] rated_torque): the torques "
            "would be scaled wrong"
        )
    configure = drv.config.pdo_mapping == "configure"
    velocity = drv.config.velocity_source == "pdo"
    for pdo in pdo_setup.wanted(mode, n, velocity):
        drv.pdos_written += pdo_setup.set_up(read, write, pdo, configure, who)
    modes = optional(read, p.OD_SUPPORTED_DRIVE_MODES)
    bit = p.SUPPORTED_MODE_BIT[mode]
    if modes is not None and not modes >> bit & 1:
        raise DriverInitializationError(
            f"{who}: supported drive modes 0x6502 = 0x{modes:08X} lacks "
            f"{p.MODE_NAMES[mode]} (bit {bit}; [drives] mode)"
        )
    fe_ms = max(1, round(drv.config.following_error_timeout * 1000))
    write(p.OD_MODES_OF_OPERATION, 0, mode, 1)
    write(p.OD_PRODUCER_HEARTBEAT, 0, hb_ms, 2)
    write(p.OD_ABORT_CONNECTION, 0, p.ABORT_CONNECTION_QUICK_STOP, 2)
    write(p.OD_MAX_TORQUE, 0, int(drv._max_torque_pm[c]), 2)
    write(p.OD_SYNC_COUNTER_OVERFLOW, 0, p.SYNC_COUNTER_OVERFLOW, 1)
    if drv._position[c]:  # the drive stops its winch when it cannot follow (docs/control.md)
        write(p.OD_FOLLOWING_ERROR_WINDOW, 0, int(drv._following_window[c]), 4)
        write(p.OD_FOLLOWING_ERROR_TIMEOUT, 0, fe_ms, 2)
    shown = sdo.read(c, p.OD_MODES_DISPLAY, 0, timeout)
    if shown != mode:
        raise DriverInitializationError(
            f"{who} reports mode {shown} in 0x6061, expected {mode} "
            f"({p.MODE_NAMES[mode]}, [drives] mode)"
        )
