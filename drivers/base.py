"""The hardware abstraction for a set of winch drives.

Modelled on python-can's ``BusABC`` (the public methods live here; a protocol subclasses it once
and overrides only the ``_``-prefixed hooks: one layer) and ros2_control's hardware-interface
lifecycle. The medium is not a hook: the driver is composed with a :class:`Transport` object
(``drivers/transport.py``: python-can buses) that it opens, closes and brackets each cycle's
frames with; the protocol sends and reads through it.

``UNCONFIGURED --configure()--> INACTIVE --activate()--> ACTIVE --deactivate()--> INACTIVE``;
``shutdown()`` from any state ends in ``FINALIZED`` (safe twice). A fault seen in ``read`` or
``write`` moves to ``ERROR``; ``recover()`` (fault reset, drives disabled) returns to ``INACTIVE``
when the cause is gone.

State per winch is SI at the motor shaft: position (rad), velocity (rad/s), torque (N·m), a
:class:`DriveState` and the age of the last feedback (s). Commands are N·m. Drive units (counts,
per-mille) are converted once, at this edge, by the protocol subclass.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers import blocking
from drivers.command_kernels import clamp_kernel, finite_into
from drivers.errors import DriverError, DriverOperationError
from drivers.liveness import Liveness
from drivers.vocabulary import (
    ACTIVE,
    ERROR,
    FINALIZED,
    INACTIVE,
    UNCONFIGURED,
    DriverStats,
    DriveState,
    Lifecycle,
    WinchStates,
)

_LOG = logging.getLogger("cdprctl.drivers")

if TYPE_CHECKING:
    from cdprctl.model.drives import DrivesConfig
    from cdprctl.model.robot import RobotModel
    from drivers.transport import Transport


class WinchDriver(ABC):
    """A set of winch drives; one per robot. See the module docstring for the lifecycle."""

    #: registry name (config ``[drives] driver = ...``)
    name: str = ""
    #: what the drive is called in messages, and what its cyclic feedback is
    drive_label = "drive"
    feedback_label = "feedback"
    #: the medium, set by the protocol's constructor (``drivers/transport.CanTransport``)
    transport: Transport

    def __init__(
        self,
        model: RobotModel,
        drives: DrivesConfig | None = None,
        *,
        period: float = 0.002,
        clock: Callable[[], float] = time.monotonic,
        wait: Callable[[float], None] | None = None,
        bus_overrides: dict[str, Any] | None = None,
    ):
        """``period`` (s): the control period; ``clock``: the time base of ``read``/``write``
        calls made without a time; ``wait(dt)``: how blocking set-up calls let time pass (a
        real sleep, or a lock-step simulator advancing its clock); ``bus_overrides``:
        ``interface``/``channel`` replacing the config's (CLI ``--can-interface``...)."""
        self.model = model
        self.config = drives if drives is not None else model.drives
        self.m = model.n_cables
        self.period = period
        self.clock = clock
        self.wait = wait if wait is not None else time.sleep
        self.bus_overrides = dict(bus_overrides or {})
        self.lifecycle = UNCONFIGURED
        self.error: DriverError | None = None
        self.warnings: list[str] = []
        self.states = WinchStates(self.m)
        self.stats = DriverStats()
        self.sent_at = -math.inf  # s (clock): when the last write's frames went out
        self.torque_limit = np.array([c.winch.torque_limit for c in model.cables])
        self.encoder_cpr = np.array([c.winch.encoder_counts_per_rev for c in model.cables])
        self._last_command = np.zeros(self.m)
        self._command = np.zeros(self.m)
        # rad, motor side: each winch's position target, for drives in position mode
        # ([drives] mode = "csp"); ``write`` takes it with the torques (their feed-forward)
        self.targets = np.zeros(self.m)
        # per drive: reset since cdprctl last set it up (an incremental encoder lost its
        # zero); None: this protocol cannot tell
        self.reset_since_setup: list[bool] | None = None
        self._activating = False
        self._recover_until = -math.inf
        self.liveness = Liveness.of_winches(model.cables, period, self.stats, self.config)

    # -- lifecycle (outside the loop: may block, may raise) -----------------------------------
    def configure(self, timeout: float = 2.0) -> None:
        """Check the bus-load budget at this period, open the buses and wait for live
        feedback from every drive → ``INACTIVE``. A bus above 70 % load is a warning
        (``self.warnings``, logged), above 100 % a :class:`DriverConfigurationError`."""
        from drivers.busload import check_bus_load
        from drivers.errors import DriverConfigurationError

        self.require(UNCONFIGURED)
        self._warm_up()
        self.warnings, errors = check_bus_load(self.config, 1.0 / self.period,
                                               self.model.sensors.load_cells)  # fmt: skip
        for w in self.warnings:
            _LOG.warning(w)
        if errors:
            raise DriverConfigurationError("; ".join(errors))
        try:
            self._open()
            self._configure_drives(timeout)
        except DriverError:
            self._close()
            raise
        self.lifecycle = INACTIVE

    def activate(self, timeout: float = 2.0) -> None:
        """Enable every drive (zero torque, targets where the motors stand) → ``ACTIVE``;
        blocks (``drivers/blocking.py``: ``begin_activate`` and the cycles it needs)."""
        blocking.activate(self, timeout)

    def deactivate(self, timeout: float = 1.0) -> None:
        """Disable the drives (brakes hold) → ``INACTIVE``; blocks (``drivers/blocking.py``)."""
        blocking.deactivate(self, timeout)

    def recover(self, timeout: float = 1.0) -> None:
        """From ``ERROR``: reset drive faults, keep the drives disabled, and return to
        ``INACTIVE`` once every drive answers again without a fault; blocks
        (``drivers/blocking.py``)."""
        blocking.recover(self, timeout)

    # -- non-blocking lifecycle, for a running loop ------------------------------------------
    def begin_activate(self) -> None:
        """Start enabling the drives; the cyclic ``read`` moves to ``ACTIVE`` once every drive
        reports enabled. Torques written meanwhile are passed on (a drive applies them from
        the moment it is enabled: send the holding torques, so releasing the brake is not a
        fall)."""
        self.require(INACTIVE)
        self._activating = True
        self.targets[:] = self.states.position  # held where they stand until targets come
        self._request_enable(True)

    def begin_deactivate(self) -> None:
        """Disable the drives (brakes hold) → ``INACTIVE`` at once; zero torque from now on."""
        self._activating = False
        self._request_enable(False)
        if self.lifecycle is ACTIVE:
            self.lifecycle = INACTIVE

    def begin_recover(self, settle: float = 0.5) -> None:
        """From ``ERROR``: fault reset, drives disabled; faults still latched during ``settle``
        seconds are ignored; back in ``INACTIVE`` at once (``ERROR`` again if they persist)."""
        if self.lifecycle is not ERROR:
            return
        self.error = None
        self._activating = False
        self._request_enable(False)
        self._fault_reset()
        self._recover_until = self.clock() + settle
        self.lifecycle = INACTIVE

    def command_brake(self, c: int, closed: bool, timeout: float) -> None:
        """Cable index ``c``'s holding brake closed whatever its power stage does
        (``closed``), or given back to the drive's own logic: a brake test pushes an enabled
        motor against it (docs/safety.md). Configured drives, outside the loop, each SDO
        answered within ``timeout`` s; a DriverError where the drives cannot."""
        raise DriverOperationError(
            f"the {self.name} driver cannot command a holding brake: test the brakes with "
            "the drives' own tools (docs/safety.md)"
        )

    def shutdown(self) -> None:
        """Disable the drives if possible and close the buses; safe to call twice."""
        if self.lifecycle is FINALIZED:
            return
        if self.lifecycle in (ACTIVE, ERROR):
            with contextlib.suppress(Exception):
                self.deactivate(timeout=0.2)
        self._close()
        self.lifecycle = FINALIZED

    def __enter__(self) -> WinchDriver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()

    # -- the cyclic path (never raises) ------------------------------------------------------
    def read(self, t: float | None = None) -> WinchStates:
        """Drain the feedback received so far; SI states, ages, faults. Never raises."""
        if self.lifecycle in (UNCONFIGURED, FINALIZED):
            return self.states
        now = self.clock() if t is None else t
        self.states.stamp = now
        try:
            err = self._read_cycle(now)
        except Exception as exc:  # the loop never sees an exception
            err = DriverOperationError(f"read failed: {type(exc).__name__}: {exc}")
        if err is not None and now < self._recover_until:
            err = None  # a fault reset in progress: the latched fault is still reported
        if err is not None:
            self._fail(err)
        elif (
            self._activating
            and self.lifecycle is INACTIVE
            and bool(np.all(self.states.state == DriveState.ENABLED))
        ):
            self._activating = False
            self.lifecycle = ACTIVE
        return self.states

    def write(
        self,
        t: float | None,
        torques: np.ndarray,
        force: bool = False,
        targets: np.ndarray | None = None,
    ) -> None:
        """Send motor torques (N·m), clamped to each winch's limit; non-finite values are
        replaced by the last valid command. Only applied while ``ACTIVE`` (zero otherwise,
        the drives being disabled). In position mode also each winch's position ``targets``
        (rad; a non-finite one keeps the last valid target, none keeps them all): the
        torques are their feed-forward. Never raises."""
        if self.lifecycle in (UNCONFIGURED, FINALIZED):
            return
        now = self.clock() if t is None else t
        cmd = self._command
        torques = np.asarray(torques, dtype=float)
        if torques.shape != cmd.shape:  # not one torque per winch: none is trusted
            torques = np.full(self.m, math.nan)
        rejected, clamped = clamp_kernel(torques, self._last_command, self.torque_limit, cmd)
        if rejected or clamped:
            self.stats.commands(rejected, clamped)
        if self.lifecycle is not ACTIVE and not force and not self._activating:
            cmd[:] = 0.0
        np.copyto(self._last_command, cmd)  # no view built, as a slice would
        if targets is not None and targets.shape == self.targets.shape:
            finite_into(targets, self.targets)
        elif self.lifecycle is not ACTIVE and not self._activating:
            # the drives are off: the targets follow the motors, so that an enable without
            # targets given holds each motor where it stands instead of driving it to zero
            self.targets[:] = self.states.position
        try:
            err = self._write_cycle(now, cmd)
        except Exception as exc:
            err = DriverOperationError(f"write failed: {type(exc).__name__}: {exc}")
        self.sent_at = self._sent_instant()
        self.stats.cycle()
        if err is not None:
            self._fail(err)

    # -- helpers ------------------------------------------------------------------------------
    def _fail(self, err: DriverError) -> None:
        self._activating = False
        if self.error is None:
            self.error = err
        if self.lifecycle in (INACTIVE, ACTIVE):
            self.lifecycle = ERROR
            self._request_enable(False)

    def require(self, state: Lifecycle) -> None:
        """DriverOperationError unless the driver is in ``state``."""
        if self.lifecycle is not state:
            raise DriverOperationError(
                f"{self.name}: this call needs the {state.value} state, the driver is "
                f"{self.lifecycle.value}"
            )

    def zero_commands(self) -> None:
        """The command and the last valid one zero: what an enable starts from."""
        self._command[:] = 0.0
        self._last_command[:] = 0.0

    def setup_cycle(self, now: float) -> DriverError | None:
        """One cycle of the set-up's own (zero torque, drives disabled; outside the
        lifecycle: no state change, no error latched): the feedback drained, the frames sent.
        The first error of either."""
        err = self._read_cycle(now)
        sent = self._write_cycle(now, np.zeros(self.m), setup=True)
        return err or sent

    def _read_cycle(self, t: float) -> DriverError | None:
        """Drain the feedback (``_drain``), then every cable's state (``_update_states``) and
        liveness (compiled, once per cycle); when one is wrong, the first error in cable order,
        a cable's drive fault before its timeout."""
        lv = self.liveness
        lv.fresh.fill(False)
        self._drain(t)
        gap = lv.read_gap(t)
        fault = self._update_states()
        late = lv.update(t, gap, self.states)
        if not (fault or late):
            return None
        for c in range(self.m):
            err = self._cable_fault(c) or lv.error(
                c, t, self._where(c), self.feedback_label, float(self.states.feedback_age[c])
            )
            if err is not None:
                return err
        return None

    def _write_cycle(
        self, t: float, torques: np.ndarray, setup: bool = False
    ) -> DriverError | None:
        """The cycle's frames (``_write_frames``) between the transport's ``begin_frames``
        and ``end_frames`` (a medium that batches them sends them there). ``setup``: the
        set-up's own cycling."""
        transport = self.transport
        transport.begin_frames(setup)
        err = self._write_frames(t, torques, setup)
        transport.end_frames()
        return err

    def _where(self, c: int) -> str:
        return f"{self.drive_label} of cable index {c}{self.transport.where(c)}"

    # -- the transport, driven from here ------------------------------------------------------
    def _open(self) -> None:
        self.transport.open()

    def _close(self) -> None:
        self.transport.close()

    @property
    def _batching(self) -> bool:
        """Whether the transport stages the frames now (``begin_frames``); set by hand, a
        test stages frames outside a cycle (tests/drivers/test_udp_bus.py)."""
        return self.transport.batching

    @_batching.setter
    def _batching(self, on: bool) -> None:
        self.transport.batching = on

    def _flush_staged(self) -> None:
        self.transport.flush_staged()

    # -- hooks: the one layer a protocol implements --------------------------------------------
    def _warm_up(self) -> None:
        """Call the cyclic path's compiled kernels once, on copies, before the drives start:
        a first call compiles (seconds) or loads from numba's cache (ms), neither of which
        belongs in the loop (cdprctl/control/lifecycle/warm_up.py). Extend it with the driver's
        own."""
        clamp_kernel(self._command, self._last_command.copy(), self.torque_limit, np.zeros(self.m))
        finite_into(self.targets, self.targets.copy())
        self.liveness.warm_up(self.states)

    def _sent_instant(self) -> float:
        """s (clock): when the drives take the last write's frames: by default now, after
        them (``sent_at``)."""
        return self.clock()

    # the protocol: set-up (outside the loop), then the cyclic path
    @abstractmethod
    def _configure_drives(self, timeout: float) -> None:
        """Start the drives' communication and wait for their first feedback (may block via
        ``self.wait``: ``blocking.await_first_feedback``); set ``liveness.started``."""

    @abstractmethod
    def _request_enable(self, enable: bool) -> None:
        """Ask the cyclic path to bring every drive to enabled (True) or disabled (False)."""

    @abstractmethod
    def _fault_reset(self) -> None:
        """Ask the cyclic path to reset drive faults."""

    @abstractmethod
    def _drain(self, t: float) -> None:
        """Decode every frame received so far into the protocol's state; mark each cable's
        feedback in ``liveness`` (``fresh``, ``fb_stamp``, ``last_hb``). Never blocks."""

    @abstractmethod
    def _update_states(self) -> bool:
        """``self.states`` of every cable from the decoded feedback; True if a drive reports a
        fault (``_cable_fault`` says which)."""

    @abstractmethod
    def _cable_fault(self, c: int) -> DriverError | None:
        """Cable ``c``'s drive fault, if any."""

    @abstractmethod
    def _write_frames(self, t: float, torques: np.ndarray, setup: bool) -> DriverError | None:
        """Encode and send the cycle's frames for the torques (N·m; in position mode with
        ``self.targets``); an error when sending keeps failing, never raise. ``setup``: a
        write of the set-up's own cycling, not of the control loop."""
