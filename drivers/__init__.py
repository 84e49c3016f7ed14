"""Hardware abstraction for winch drives over python-can (see drivers.base)."""

import cdprctl  # noqa: F401  first: the kernels' cache chosen before any is compiled (core/kernel_cache.py)
from drivers.base import WinchDriver
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
from drivers.registry import create_driver, driver_names, register_driver
from drivers.vocabulary import DriveState, Lifecycle, WinchStates

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
