"""Hardware abstraction for winch drives over python-can (see drivers.base)."""

from drivers.base import (
    DriveState,
    Lifecycle,
    WinchDriver,
    WinchStates,
    create_driver,
    driver_names,
    register_driver,
)
from drivers.cia402.driver import Cia402Driver
from drivers.errors import (
    DriveFaultError,
    DriverConfigurationError,
    DriverError,
    DriverInitializationError,
    DriverOperationError,
    DriverTimeoutError,
)
from drivers.odrive.driver import ODriveDriver

__all__ = [
    "Cia402Driver",
    "DriveFaultError",
    "DriveState",
    "DriverConfigurationError",
    "DriverError",
    "DriverInitializationError",
    "DriverOperationError",
    "DriverTimeoutError",
    "Lifecycle",
    "ODriveDriver",
    "WinchDriver",
    "WinchStates",
    "create_driver",
    "driver_names",
    "register_driver",
]
