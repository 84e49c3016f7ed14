"""The holding brake commanded by the master, for a brake test (docs/safety.md): CiA 402's
digital outputs (0x60FE), whose bit 0 is "set brake" — the brake closed whatever the power
stage does, so an enabled drive can push against it. Sub-index 2 is the bit mask that lets
the master drive an output (Elmo, Technosoft, Pilz have it; maxon EPOS4 and Nanotec do not:
there sub-index 1 alone, once the drive's holding-brake output is configured). Outside the
loop only (SDO)."""

from __future__ import annotations

from drivers.cia402 import protocol as p
from drivers.cia402.sdo_client import SdoClient
from drivers.errors import DriverInitializationError, SdoAbortError

OD_DIGITAL_OUTPUTS = 0x60FE
SUB_PHYSICAL_OUTPUTS = 1
SUB_BIT_MASK = 2
SET_BRAKE = 0x1  # bit 0 of both sub-indices (CiA 402-2, 0x60FE)


def command_brake(sdo: SdoClient, c: int, closed: bool, timeout: float) -> None:
    """The brake of cable index ``c`` closed by the master (``closed``) or given back to the
    drive's own brake logic; read back, DriverInitializationError when the drive did not take
    it (a drive that ignores the bit would open its brake on enable: the test would then be
    no test)."""
    try:
        mask = sdo.read(c, OD_DIGITAL_OUTPUTS, SUB_BIT_MASK, timeout, signed=False)
    except SdoAbortError as exc:
        if exc.code != p.SDO_ABORT_NO_SUB:
            raise
        mask = None  # no mask: sub-index 1 acts alone
    if mask is not None:
        mask = (mask | SET_BRAKE) if closed else (mask & ~SET_BRAKE)
        sdo.write(c, OD_DIGITAL_OUTPUTS, SUB_BIT_MASK, mask, 4, timeout)
    outputs = sdo.read(c, OD_DIGITAL_OUTPUTS, SUB_PHYSICAL_OUTPUTS, timeout, signed=False)
    outputs = (outputs | SET_BRAKE) if closed else (outputs & ~SET_BRAKE)
    sdo.write(c, OD_DIGITAL_OUTPUTS, SUB_PHYSICAL_OUTPUTS, outputs, 4, timeout)
    back = sdo.read(c, OD_DIGITAL_OUTPUTS, SUB_PHYSICAL_OUTPUTS, timeout, signed=False)
    if bool(back & SET_BRAKE) != closed:
        raise DriverInitializationError(
            f"cable index {c}: the drive did not take 'set brake' (0x60FE:01 bit 0 reads "
            f"{back & SET_BRAKE} after writing {int(closed)}): configure its holding-brake "
            "output to be commanded over CANopen (docs/safety.md)"
        )


def brake_commanded(value: int, mask: int | None) -> bool:
    """Whether 0x60FE's sub-indices (``mask`` None: the drive has no bit mask) close the
    brake: the simulated drives' reading of them."""
    return bool(value & SET_BRAKE) and (mask is None or bool(mask & SET_BRAKE))
