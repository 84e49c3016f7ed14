"""The drives as the control side sees them: the manager owns the driver (its read and write,
its set-up); the controller and the supervisor get this view (``supervisor.DrivePort``): the
lifecycle, its error, the feedback, and the lifecycle requests. No read, no write, no bus: the
controller cannot reach the driver around the manager."""

from __future__ import annotations

from drivers.base import WinchDriver
from drivers.errors import DriverError
from drivers.vocabulary import Lifecycle, WinchStates


class DriveView:
    __slots__ = ("_driver",)

    def __init__(self, driver: WinchDriver):
        self._driver = driver

    @property
    def lifecycle(self) -> Lifecycle:
        return self._driver.lifecycle

    @property
    def error(self) -> DriverError | None:
        return self._driver.error

    @property
    def states(self) -> WinchStates:
        """The feedback the manager's last read wrote (SI, motor side)."""
        return self._driver.states

    def begin_activate(self) -> None:
        self._driver.begin_activate()

    def begin_deactivate(self) -> None:
        self._driver.begin_deactivate()

    def begin_recover(self, settle: float = 0.5) -> None:
        self._driver.begin_recover(settle)
