"""What a CiA 402 drive can do, read by SDO before anything is written to it: identity (0x1018),
device type (0x1000), supported drive modes (0x6502), rated torque (0x6076), and which of the
optional objects cdprctl writes it has. Read-only; shared by the set-up (``drive_setup``),
which refuses a drive that cannot do the job before touching its mapping, and by ``cdprctl
drives scan``, which only reports. An object the drive lacks, or holds no value in, reads as
None: CiA 402 makes most of these optional, and vendors' files leave some without a value."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from drivers.cia402 import protocol as p
from drivers.errors import SdoAbortError

Read = Callable[[int, int], int]  # (index, sub) → value, unsigned; raises SdoAbortError

CIA402_PROFILE = 402  # 0x1000 bits 0-15: the device profile number (CiA 301 §7.5.2.1)


def optional(read: Read, index: int, sub: int = 0) -> int | None:
    """An object a drive may not have (CiA 402 optional) or hold no value in: None when it
    aborts."""
    try:
        return read(index, sub)
    except SdoAbortError:
        return None


def identity(read: Read) -> dict[str, int] | None:
    """0x1018 (CiA 301 mandatory, but sub-indices 2-4 optional): what the drive has."""
    ident = {
        name: optional(read, p.OD_IDENTITY, sub)
        for sub, name in ((1, "vendor_id"), (2, "product_code"), (3, "revision"), (4, "serial"))
    }
    return {k: v for k, v in ident.items() if v is not None} or None


@dataclass
class Capabilities:
    """One drive, as read; None where the drive has no such object or no value in it."""

    identity: dict[str, int] | None
    device_type: int | None  # 0x1000
    modes: int | None  # 0x6502, a bit per mode (CiA 402 Table 84)
    rated_torque: int | None  # 0x6076, mN·m
    # the optional objects cdprctl writes (drive_setup.OPTIONAL) that the drive has
    present: dict[int, bool] = field(default_factory=dict)

    def can_run(self, mode: int) -> str | None:
        """Why this drive cannot run cdprctl in ``mode`` (None: nothing it declares says it
        cannot). Device type first: a drive of another profile has no 0x6502 to ask."""
        if self.device_type is not None and self.device_type & 0xFFFF != CIA402_PROFILE:
            profile = self.device_type & 0xFFFF
            return (f"device type 0x1000 = 0x{self.device_type:08X} is profile {profile}, "
                    "not CiA 402 (drives and motion control)")  # fmt: skip
        bit = p.SUPPORTED_MODE_BIT[mode]
        if self.modes is not None and not self.modes >> bit & 1:
            return (f"supported drive modes 0x6502 = 0x{self.modes:08X} lacks "
                    f"{p.MODE_NAMES[mode]} (bit {bit}; [drives] mode)")  # fmt: skip
        return None

    def modes_text(self) -> str:
        """The cyclic synchronous modes 0x6502 lists, for people."""
        if self.modes is None:
            return "0x6502 not readable: the mode is tried at set-up"
        have = [name for mode, name in p.MODE_SHORT_NAMES.items()
                if self.modes >> p.SUPPORTED_MODE_BIT[mode] & 1]  # fmt: skip
        return f"0x6502 = 0x{self.modes:08X} ({', '.join(have) or 'no csp, no cst'})"


def rated_torque_problem(rated: int | None, want_mnm: float) -> str | None:
    """0x6076 (mN·m) against ``[drives] rated_torque`` (``want_mnm``), the unit of every torque
    per mille: why it cannot run (None: it matches within 1 %, or the drive has none)."""
    if rated is None or abs(rated - want_mnm) <= 0.01 * want_mnm:
        return None
    unset = " (not set: set the motor's data with the vendor's tool, or in a DCF)" if (
        rated == 0) else ""  # fmt: skip
    return (f"rated torque 0x6076 is {rated} mN·m{unset}, the config says {want_mnm:.0f} mN·m "
            "([drives] rated_torque): the torques would be scaled wrong")  # fmt: skip


def read_capabilities(read: Read, optional_objects: tuple[int, ...]) -> Capabilities:
    """The drive's capabilities, by uploads only. ``optional_objects``: the indices whose
    presence to note (an upload that aborts 0x06020000 or 0x06090011: absent)."""
    ident = identity(read)
    device_type = optional(read, p.OD_DEVICE_TYPE)
    modes = optional(read, p.OD_SUPPORTED_DRIVE_MODES)
    rated = optional(read, p.OD_RATED_TORQUE)
    present = {}
    for index in optional_objects:
        try:
            read(index, 0)
            present[index] = True
        except SdoAbortError as exc:  # no value (0x060A0023) or write-only: there, all the same
            present[index] = exc.code not in (p.SDO_ABORT_NO_OBJECT, p.SDO_ABORT_NO_SUB)
    return Capabilities(ident, device_type, modes, rated, present)
