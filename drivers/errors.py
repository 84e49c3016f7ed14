"""Typed errors of the drivers (in the spirit of python-can's CanError hierarchy).

The cyclic ``read``/``write`` never raise: they record one of these in ``driver.error`` and move
the lifecycle to ``ERROR``. The set-up calls (``configure``, ``activate``, ...) raise them.
"""

from __future__ import annotations


class DriverError(Exception):
    """Base of every driver error."""


class DriverConfigurationError(DriverError):
    """The drive configuration is invalid (a config file, a bus option, a bus-load budget)."""


class DriverInitializationError(DriverError):
    """A bus could not be opened, or a drive did not answer during set-up."""


class SdoAbortError(DriverInitializationError):
    """A drive aborted an SDO transfer; ``code`` is CiA 301's abort code."""

    def __init__(self, message: str, node_id: int, index: int, sub: int, code: int):
        super().__init__(message)
        self.node_id, self.index, self.sub, self.code = node_id, index, sub, code


class DriverOperationError(DriverError):
    """An operation failed: a send error, a lifecycle call in the wrong state."""


class DriverTimeoutError(DriverError):
    """A drive stayed silent: no feedback, no heartbeat, no SDO answer in time."""

    def __init__(self, message: str, cable: int | None = None):
        super().__init__(message)
        self.cable = cable


def following_error_text(off: float, window: float, m_per_rad: float, timeout: float,
                         checked_by: str) -> str:  # fmt: skip
    """A following error as a user reads it: how far the motor was off its position target
    (``off`` rad at the motor; in mm of cable by ``m_per_rad``), against the window (rad) and
    time-out (s) of [drives], and who checked it (the drive's 0x6065/0x6066, or cdprctl)."""
    return (f"following error: {off * m_per_rad * 1e3:.2f} mm of cable ({off:.4f} rad at the "
            f"motor) off its position target, beyond [drives] following_error_window = "
            f"{window * m_per_rad * 1e3:.2f} mm ({window:.4f} rad) for more than "
            f"following_error_timeout = {timeout * 1e3:.0f} ms ({checked_by})")  # fmt: skip


class DriveFaultError(DriverError):
    """A drive reported a fault; ``code`` is the drive's error code, ``description`` decodes it."""

    def __init__(self, cable: int, node_id: int, code: int, description: str):
        super().__init__(
            f"drive of cable index {cable} (node {node_id}) fault 0x{code:04X}: {description}"
        )
        self.cable = cable
        self.node_id = node_id
        self.code = code
        self.description = description


class SafeTorqueOffError(DriveFaultError):
    """A drive reports safe torque off (its STO input open: the e-stop's safety chain, by one of
    ``protocol.STO_CODES``): not a fault of the drive's; it has no torque, its brake holds, and
    it takes no fault reset until the chain is closed (docs/safety.md)."""
