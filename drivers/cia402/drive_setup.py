"""The set-up of one CiA 402 drive, by SDO in PRE-OPERATIONAL, at every start, after its
capabilities (``capabilities``) said it can do the job: a DCF's ParameterValues first (cdprctl's
own settings below win), the rated torque (0x6076) against the config, then what the job needs —
the PDO mapping the cyclic codec uses (``pdo_setup``), the mode (0x6060, shown back in 0x6061),
the heartbeat (0x1017) — refused by name when the drive will not take it, and the optional
objects (``OPTIONAL``): one the drive lacks, refuses or whose range excludes cdprctl's value
is skipped, and the drive's ``skipped`` list says what is lost and what cdprctl does instead.
Outside the loop; raises DriverInitializationError naming the drive and the object."""

from __future__ import annotations

from typing import Any

from drivers.cia402 import pdo_setup
from drivers.cia402 import protocol as p
from drivers.cia402.capabilities import Capabilities, optional, rated_torque_problem
from drivers.cia402.dcf import parameter_values
from drivers.cia402.sdo_client import SdoClient
from drivers.errors import DriverInitializationError, SdoAbortError

# The objects cdprctl writes that a drive may go without: (name, what is lost and what cdprctl
# does instead). CiA 402 makes each optional; vendors leave them out (maxon EPOS4: no 0x6072,
# no 0x1019, 0x6066 only 0; Elmo Gold: no 0x1019).
OPTIONAL = {
    p.OD_ABORT_CONNECTION: (
        "abort connection option",
        "the drive reacts to a lost controller as its own default says, not by a quick stop",
    ),
    p.OD_MAX_TORQUE: (
        "max torque",
        "no torque limit in the drive: cdprctl's own clamp to the winch's limit is the only one",
    ),
    p.OD_SYNC_COUNTER_OVERFLOW: (
        "SYNC counter overflow",
        "the SYNC on its bus goes without a counter: a drive that misses a SYNC may take the "
        "target of the next one a period late (docs/drivers.md, 'The SYNC counter')",
    ),
    p.OD_FOLLOWING_ERROR_WINDOW: (
        "following error window",
        "the drive does not stop on its own following error: cdprctl's tracking checks only",
    ),
    p.OD_FOLLOWING_ERROR_TIMEOUT: (
        "following error time out",
        "the drive's own time out applies to its following-error stop",
    ),
}
# the optional objects written in position mode alone (the drive's own following-error stop)
POSITION_ONLY = (p.OD_FOLLOWING_ERROR_WINDOW, p.OD_FOLLOWING_ERROR_TIMEOUT)
# what an optional object's write may meet and still be skipped: absent, read-only, another
# size, the value out of the drive's range
SKIPPABLE = {p.SDO_ABORT_NO_OBJECT, p.SDO_ABORT_NO_SUB, p.SDO_ABORT_READ_ONLY, 0x06070010,
             0x06090030, 0x06090031, 0x06090032}  # fmt: skip


def abort_text(code: int) -> str:
    """An SDO abort code in words, with its number."""
    return f"{p.SDO_ABORT_TEXT.get(code, 'SDO abort')} (0x{code:08X})"


def configure_drive(
    drv: Any, sdo: SdoClient, c: int, timeout: float, caps: Capabilities, sync_counter: bool
) -> None:
    """The set-up of the drive of cable index ``c`` (its capabilities ``caps`` already read
    and accepted); ``sync_counter``: the SYNC on its medium carries the counter (every drive
    there has 0x1019), else 0x1019 := 0 where a drive has it."""
    n = int(drv.node[c])
    who = f"drive of cable index {c} (node {n})"
    mode = drv.modes[c]
    skipped = drv.skipped[c]
    skipped.clear()

    def read(index: int, sub: int) -> int:
        return sdo.read(c, index, sub, timeout, signed=False)

    def write(index: int, sub: int, value: int, size: int) -> None:
        sdo.write(c, index, sub, value, size, timeout)

    def needed(index: int, value: int, size: int, why: str) -> None:
        try:
            write(index, 0, value, size)
        except SdoAbortError as exc:
            raise DriverInitializationError(
                f"{who}: refused 0x{index:04X} := {value} ({why}): {abort_text(exc.code)}"
            ) from exc

    def optional_write(index: int, value: int, size: int) -> None:
        name, lost = OPTIONAL[index]
        try:
            write(index, 0, value, size)
        except SdoAbortError as exc:
            if exc.code not in SKIPPABLE:
                raise
            skipped.append(f"0x{index:04X} {name} := {value} skipped, "
                           f"{abort_text(exc.code)}: {lost}")  # fmt: skip

    drv.identities[c] = caps.identity
    # Five heartbeats per timeout: with three (167 ms of 0.5 s) the loop's 4 ms ticks left
    # two in some windows, and two lost frames in a row at 5 % loss stopped the robot as
    # a lost drive (lock-step reliability matrix, 1 of 3 seeds); five is 10 Hz, the rate
    # the bus-load budget counts
    hb_ms = round(drv.config.heartbeat_timeout * 1000 / 5)  # ≥ 2: [drives] heartbeat_timeout
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
    rated = optional(read, p.OD_RATED_TORQUE) if dcf else caps.rated_torque  # a DCF may set it
    check_rated_torque(drv, who, rated, skipped)
    configure = drv.config.pdo_mapping == "configure"
    velocity = drv.config.velocity_source == "pdo"
    for pdo in pdo_setup.wanted(mode, n, velocity):
        drv.pdos_written += pdo_setup.set_up(read, write, pdo, configure, who)
    needed(p.OD_MODES_OF_OPERATION, mode, 1, f"{p.MODE_NAMES[mode]}, [drives] mode")
    needed(p.OD_PRODUCER_HEARTBEAT, hb_ms, 2, "its heartbeat, how cdprctl knows it is there")
    optional_write(p.OD_ABORT_CONNECTION, p.ABORT_CONNECTION_QUICK_STOP, 2)
    optional_write(p.OD_MAX_TORQUE, int(drv._max_torque_pm[c]), 2)
    optional_write(p.OD_SYNC_COUNTER_OVERFLOW, p.SYNC_COUNTER_OVERFLOW if sync_counter else 0, 1)
    if not sync_counter and caps.present.get(p.OD_SYNC_COUNTER_OVERFLOW):
        skipped.append("the SYNC counter (0x1019 := 0): another drive on its bus has none")
    if drv._position[c]:  # the drive stops its winch when it cannot follow (docs/control.md)
        fe_ms = max(1, round(drv.config.following_error_timeout * 1000))
        optional_write(p.OD_FOLLOWING_ERROR_WINDOW, int(drv._following_window[c]), 4)
        optional_write(p.OD_FOLLOWING_ERROR_TIMEOUT, fe_ms, 2)
    shown = sdo.read(c, p.OD_MODES_DISPLAY, 0, timeout)
    if shown != mode:
        raise DriverInitializationError(
            f"{who} reports mode {shown} in 0x6061, expected {mode} "
            f"({p.MODE_NAMES[mode]}, [drives] mode)"
        )


def check_rated_torque(drv: Any, who: str, rated: int | None, skipped: list[str]) -> None:
    """0x6076 (mN·m) against ``[drives] rated_torque`` (``capabilities.rated_torque_problem``):
    a drive without it is noted, one that differs refused."""
    want = drv.rated_torque * 1000.0
    if rated is None:
        skipped.append(
            f"0x6076 motor rated torque: the drive has none to check; torques in per mille "
            f"of {want:.0f} mN·m ([drives] rated_torque) as the config says"
        )
    elif (why := rated_torque_problem(rated, want)) is not None:
        raise DriverInitializationError(f"{who}: {why}")
