"""The set-up of one CiA 402 drive, by SDO in PRE-OPERATIONAL, at every start, after its
capabilities (``capabilities``) said it can do the job: a DCF's ParameterValues first (cdprctl's
own settings below win), the rated torque (0x6076) against the config, then what the job needs —
the PDO mapping the cyclic codec uses (``pdo_setup``), the mode (0x6060, shown back in 0x6061),
the heartbeat (0x1017) — refused by name when the drive will not take it, and the optional
objects (``OPTIONAL``): one the drive lacks, refuses or whose range excludes cdprctl's value
is skipped, and the drive's ``skipped`` list says what is lost and what cdprctl does instead.
Outside the loop; raises DriverInitializationError naming the drive and the object.

Its port on the driver is explicit: a :class:`DrivePlan` says what to write (the driver's
decisions from the config, ``plans``), a :class:`DriveRecord` takes what was found and done,
and the SDO client carries the transfers."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.cia402 import pdo_setup
from drivers.cia402 import protocol as p
from drivers.cia402.capabilities import Capabilities, optional, rated_torque_problem
from drivers.cia402.dcf import parameter_values
from drivers.cia402.sdo_client import SdoClient
from drivers.errors import DriverInitializationError, SdoAbortError

if TYPE_CHECKING:
    from cdprctl.model.drives import DrivesConfig

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


@dataclass(frozen=True)
class DrivePlan:
    """What cdprctl's set-up writes to the drive of one cable."""

    cable: int
    node: int
    mode: int  # 0x6060 (p.MODE_CSP or p.MODE_CST)
    dcf: str  # its DCF ([[drives.buses]] dcf), whose ParameterValues go first; "": none
    heartbeat_ms: int  # 0x1017, the drive's producer heartbeat time
    rated_torque: float  # N·m per 1000 per-mille ([drives] rated_torque), checked on 0x6076
    max_torque_pm: int  # 0x6072: its winch's torque limit, per mille of the rated torque
    following_window: int  # 0x6065 (counts), position mode
    following_timeout_ms: int  # 0x6066, position mode
    configure_pdos: bool  # [drives] pdo_mapping = "configure" (else only checked)
    velocity_pdo: bool  # [drives] velocity_source = "pdo": the velocity's TPDO2 mapped too

    @property
    def position(self) -> bool:
        """The drive follows position targets (CSP): its own following-error stop is set."""
        return self.mode == p.MODE_CSP


@dataclass
class DriveRecord:
    """What the set-up of one drive found and did, filled as it goes (a set-up that fails
    leaves what it got to): its identity (0x1018), whether it was reset since cdprctl last
    set it up (None: not read yet), the optional objects skipped and why, the PDOs written."""

    identity: dict[str, int] | None = None
    reset: bool | None = None
    skipped: list[str] = field(default_factory=list)
    pdos_written: int = 0


def plans(cfg: DrivesConfig, cables: Sequence[Any], node: np.ndarray, modes: Sequence[int],
          encoder_cpr: np.ndarray) -> list[DrivePlan]:  # fmt: skip
    """The plan of each cable's drive: ``cfg`` the ``[drives]`` section, ``cables`` the
    model's, ``node`` and ``modes`` per cable, ``encoder_cpr`` counts per motor turn."""
    dcf = [""] * len(cables)
    for bus in cfg.buses:
        for k, cable in enumerate(bus.cables):
            dcf[cable] = bus.dcf_of(k)
    # Five heartbeats per timeout: with three (167 ms of 0.5 s) the loop's 4 ms ticks left
    # two in some windows, and two lost frames in a row at 5 % loss stopped the robot as
    # a lost drive (lock-step reliability matrix, 1 of 3 seeds); five is 10 Hz, the rate
    # the bus-load budget counts
    hb_ms = round(cfg.heartbeat_timeout * 1000 / 5)  # ≥ 2: [drives] heartbeat_timeout
    fe_ms = max(1, round(cfg.following_error_timeout * 1000))
    return [
        DrivePlan(
            cable=c, node=int(node[c]), mode=modes[c], dcf=dcf[c], heartbeat_ms=hb_ms,
            rated_torque=cfg.rated_torque,
            max_torque_pm=int(min(0xFFFF, round(
                cable.winch.torque_limit / cfg.rated_torque * 1000.0))),
            following_window=int(max(1, min(p.FOLLOWING_ERROR_OFF - 1, round(
                cfg.following_error_window_rad(cable.winch) / (2.0 * math.pi) * encoder_cpr[c]
            )))),
            following_timeout_ms=fe_ms, configure_pdos=cfg.pdo_mapping == "configure",
            velocity_pdo=cfg.velocity_source == "pdo",
        )
        for c, cable in enumerate(cables)
    ]  # fmt: skip


def abort_text(code: int) -> str:
    """An SDO abort code in words, with its number."""
    return f"{p.SDO_ABORT_TEXT.get(code, 'SDO abort')} (0x{code:08X})"


def configure_drive(
    sdo: SdoClient, plan: DrivePlan, record: DriveRecord, timeout: float, caps: Capabilities,
    sync_counter: bool,
) -> None:  # fmt: skip
    """The set-up of the drive ``plan`` says (its capabilities ``caps`` already read and
    accepted), each SDO answered within ``timeout`` s; what it finds and does goes into
    ``record``. ``sync_counter``: the SYNC on its medium carries the counter (every drive
    there has 0x1019), else 0x1019 := 0 where a drive has it."""
    c, n, mode = plan.cable, plan.node, plan.mode
    who = f"drive of cable index {c} (node {n})"
    skipped = record.skipped
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

    record.identity = caps.identity
    # before a DCF can write it
    record.reset = optional(read, p.OD_PRODUCER_HEARTBEAT) != plan.heartbeat_ms
    if plan.dcf:  # the integrator's parameters first; cdprctl's own settings below win
        write_dcf(write, plan.dcf, n, who)
    rated = optional(read, p.OD_RATED_TORQUE) if plan.dcf else caps.rated_torque  # DCF may set
    check_rated_torque(plan.rated_torque, who, rated, skipped)
    for pdo in pdo_setup.wanted(mode, n, plan.velocity_pdo):
        record.pdos_written += pdo_setup.set_up(read, write, pdo, plan.configure_pdos, who)
    needed(p.OD_MODES_OF_OPERATION, mode, 1, f"{p.MODE_NAMES[mode]}, [drives] mode")
    needed(p.OD_PRODUCER_HEARTBEAT, plan.heartbeat_ms, 2,
           "its heartbeat, how cdprctl knows it is there")  # fmt: skip
    optional_write(p.OD_ABORT_CONNECTION, p.ABORT_CONNECTION_QUICK_STOP, 2)
    optional_write(p.OD_MAX_TORQUE, plan.max_torque_pm, 2)
    optional_write(p.OD_SYNC_COUNTER_OVERFLOW, p.SYNC_COUNTER_OVERFLOW if sync_counter else 0, 1)
    if not sync_counter and caps.present.get(p.OD_SYNC_COUNTER_OVERFLOW):
        skipped.append("the SYNC counter (0x1019 := 0): another drive on its bus has none")
    if plan.position:  # the drive stops its winch when it cannot follow (docs/control.md)
        optional_write(p.OD_FOLLOWING_ERROR_WINDOW, plan.following_window, 4)
        optional_write(p.OD_FOLLOWING_ERROR_TIMEOUT, plan.following_timeout_ms, 2)
    shown = sdo.read(c, p.OD_MODES_DISPLAY, 0, timeout)
    if shown != mode:
        raise DriverInitializationError(
            f"{who} reports mode {shown} in 0x6061, expected {mode} "
            f"({p.MODE_NAMES[mode]}, [drives] mode)"
        )


def write_dcf(write: Any, dcf: str, node: int, who: str) -> None:
    """The ParameterValues of the DCF ``dcf`` for ``node``, each by ``write(index, sub,
    value, size)``; a refused one refuses the start."""
    for index, sub, value, size in parameter_values(dcf, node):
        try:
            write(index, sub, value, size)
        except SdoAbortError as exc:
            raise DriverInitializationError(
                f"{who}: refused 0x{index:04X}:{sub:02X} := {value} from {dcf} "
                f"(SDO abort 0x{exc.code:08X})"
            ) from exc


def check_rated_torque(rated_torque: float, who: str, rated: int | None,
                       skipped: list[str]) -> None:  # fmt: skip
    """0x6076 (mN·m) against ``[drives] rated_torque`` (``rated_torque``, N·m;
    ``capabilities.rated_torque_problem``): a drive without it is noted, one that differs
    refused."""
    want = rated_torque * 1000.0
    if rated is None:
        skipped.append(
            f"0x6076 motor rated torque: the drive has none to check; torques in per mille "
            f"of {want:.0f} mN·m ([drives] rated_torque) as the config says"
        )
    elif (why := rated_torque_problem(rated, want)) is not None:
        raise DriverInitializationError(f"{who}: {why}")
