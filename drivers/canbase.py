"""What every CAN protocol driver shares: the buses of the config, the node of each cable, and
sending (with the traffic log and a failure streak)."""

from __future__ import annotations

import contextlib
from typing import Any

import can
import numpy as np

from drivers.base import WinchDriver
from drivers.buses import TrafficLog, open_bus


class CanWinchDriver(WinchDriver):
    """A :class:`WinchDriver` on python-can buses; protocols subclass it."""

    def __init__(self, model: Any, **kwargs: Any):
        super().__init__(model, **kwargs)
        self.buses: list[can.BusABC] = []
        self.log: TrafficLog | None = None
        self.node = np.zeros(self.m, dtype=np.int64)  # CAN node id of each cable's drive
        self.bus_of = np.zeros(self.m, dtype=np.int64)  # bus index of each cable's drive
        for b, bus in enumerate(self.config.buses):
            for c, n in zip(bus.cables, bus.node_ids, strict=True):
                self.node[c], self.bus_of[c] = n, b
        self._send_fail_streak = 0

    def _open(self) -> None:
        for b, bus_cfg in enumerate(self.config.buses):
            self.buses.append(open_bus(bus_cfg, self.bus_overrides, b))
        if self.config.log_file:
            self.log = TrafficLog(self.config.log_file)

    def _close(self) -> None:
        for bus in self.buses:
            with contextlib.suppress(Exception):  # closing: nothing useful to do with it
                bus.shutdown()
        self.buses = []
        if self.log is not None:
            self.log.close()
            self.log = None

    def _send(self, b: int, msg: can.Message) -> bool:
        """Send on bus ``b`` without blocking; a failure is counted, never raised."""
        try:
            self.buses[b].send(msg, timeout=0)
        except can.CanError:
            self.stats.send_errors += 1
            self._send_fail_streak += 1
            return False
        self._send_fail_streak = 0
        self.stats.frames_sent += 1
        if self.log is not None:
            self.log(msg)
        return True
