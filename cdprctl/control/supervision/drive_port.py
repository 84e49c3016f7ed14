"""The drives as the control side sees them (``DrivePort``: their lifecycle, error and states,
and the requests it may make; the manager owns their I/O), and the fault a driver's error is."""

from __future__ import annotations

from typing import Protocol

from cdprctl.control.states import FaultKind
from drivers.errors import DriveFaultError, DriverError, DriverTimeoutError
from drivers.vocabulary import Lifecycle, WinchStates


class DrivePort(Protocol):
    """What the control side may see and ask of the drives (``drive_view.DriveView``); the
    manager owns their I/O."""

    @property
    def lifecycle(self) -> Lifecycle: ...
    @property
    def error(self) -> DriverError | None: ...
    @property
    def states(self) -> WinchStates: ...

    def begin_activate(self) -> None: ...
    def begin_deactivate(self) -> None: ...
    def begin_recover(self, settle: float = 0.5) -> None: ...


def driver_fault_kind(err: DriverError | None) -> FaultKind:
    if isinstance(err, DriveFaultError):
        return FaultKind.DRIVE_FAULT
    if isinstance(err, DriverTimeoutError):
        return FaultKind.DRIVE_SILENT
    return FaultKind.DRIVES
