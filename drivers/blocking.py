"""The blocking lifecycle calls of a driver (``activate``, ``deactivate``, ``recover``), for
set-up and tools outside a running loop, each written on the non-blocking one: its ``begin_*``,
then ``read``/``write`` cycles letting time pass with the driver's ``wait`` until the
lifecycle says it is done or the timeout passes. The control loop itself uses ``begin_*``.
``await_first_feedback`` is the set-up's own cycling, for a protocol's ``_configure_drives``.
Written on the driver's public interface alone (:class:`Stepped`, which
``drivers.base.WinchDriver`` is): this module imports no driver."""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from drivers.errors import DriverError, DriverOperationError, DriverTimeoutError
from drivers.liveness import Liveness
from drivers.vocabulary import DriveState, Lifecycle, WinchStates


class Stepped(Protocol):
    """The part of a driver the blocking calls step through (``drivers/base.py``)."""

    m: int
    period: float
    lifecycle: Lifecycle
    error: DriverError | None
    states: WinchStates
    liveness: Liveness

    def clock(self) -> float: ...
    def wait(self, dt: float) -> None: ...
    def require(self, state: Lifecycle) -> None: ...
    def zero_commands(self) -> None: ...
    def begin_activate(self) -> None: ...
    def begin_deactivate(self) -> None: ...
    def begin_recover(self, settle: float = 0.5) -> None: ...
    def setup_cycle(self, now: float) -> DriverError | None: ...
    def read(self, t: float | None = None) -> WinchStates: ...

    def write(self, t: float | None, torques: np.ndarray, force: bool = False,
              targets: np.ndarray | None = None) -> None: ...  # fmt: skip


def activate(drv: Stepped, timeout: float = 2.0) -> None:
    """Enable every drive (zero torque, targets where the motors stand) → ``ACTIVE``;
    blocks with ``wait``: ``begin_activate`` and the cycles it needs (``read`` alone says
    when every drive is enabled)."""
    drv.require(Lifecycle.INACTIVE)
    drv.zero_commands()
    drv.begin_activate()
    zeros = np.zeros(drv.m)
    deadline = drv.clock() + timeout
    while True:
        now = drv.clock()
        drv.read(now)
        drv.write(now, zeros)
        if drv.lifecycle is Lifecycle.ERROR:
            raise drv.error or DriverOperationError("activation failed")
        if drv.lifecycle is Lifecycle.ACTIVE:
            return
        if now > deadline:
            not_on = [i for i in range(drv.m) if drv.states.state[i] != DriveState.ENABLED]
            drv.begin_deactivate()
            raise DriverTimeoutError(
                f"drives of cable indices {not_on} not enabled after {timeout:g} s",
                not_on[0],
            )
        drv.wait(drv.period)


def deactivate(drv: Stepped, timeout: float = 1.0) -> None:
    """Disable the drives (brakes hold) → ``INACTIVE``: ``begin_deactivate``, then cycles of
    zero torque until no drive reports enabled (or ``timeout`` s)."""
    if drv.lifecycle not in (Lifecycle.ACTIVE, Lifecycle.ERROR):
        return
    drv.begin_deactivate()
    deadline = drv.clock() + timeout
    while drv.clock() <= deadline:
        now = drv.clock()
        drv.read(now)
        drv.write(now, np.zeros(drv.m), force=True)
        if np.all(drv.states.state != DriveState.ENABLED):
            break
        drv.wait(drv.period)


def recover(drv: Stepped, timeout: float = 1.0) -> None:
    """From ``ERROR``: ``begin_recover`` (fault reset, drives disabled; faults still latched
    are not counted for ``timeout`` s), then cycles until every drive answers again without a
    fault → ``INACTIVE``; a fault still there after ``timeout`` is raised."""
    if drv.lifecycle is not Lifecycle.ERROR:
        return
    drv.begin_recover(settle=timeout)
    deadline = drv.clock() + timeout
    while True:
        now = drv.clock()
        drv.read(now)
        drv.write(now, np.zeros(drv.m), force=True)
        if drv.lifecycle is Lifecycle.INACTIVE and np.all(
            (drv.states.state != DriveState.FAULT)
            & (drv.states.state != DriveState.UNKNOWN)
            & (drv.states.feedback_age < 10 * drv.period + 1e-9)
        ):
            return
        if now > deadline:
            drv.lifecycle = Lifecycle.ERROR
            raise drv.error or DriverTimeoutError("drives did not recover", None)
        drv.wait(drv.period)


def await_first_feedback(
    drv: Stepped, timeout: float, heard: Callable[[], bool], what: str,
    on_tick: Callable[[float], None] | None = None,
) -> None:  # fmt: skip
    """Cycle (zero torque, drives disabled) until ``heard()`` says every drive has sent
    feedback; ``on_tick(now)`` once a cycle (a repeated NMT start, say). Raises
    ``DriverTimeoutError`` naming the silent cables' indices and ``what`` was awaited."""
    deadline = drv.clock() + timeout
    while True:
        now = drv.clock()
        drv.setup_cycle(now)
        if heard():
            return
        if on_tick is not None:
            on_tick(now)
        if now > deadline:
            silent = [c for c in range(drv.m) if not np.isfinite(drv.liveness.fb_stamp[c])]
            raise DriverTimeoutError(
                f"no {what} from the drives of cable indices {silent} within {timeout:g} s",
                silent[0] if silent else None,
            )
        drv.wait(drv.period)
