"""Opening python-can buses from the config, and the optional traffic log."""

from __future__ import annotations

import errno
import queue
import threading
from typing import Any

import can

from cdprctl.model.drives import BusConfig
from drivers.errors import DriverInitializationError
from drivers.pair_bus import PairBus
from drivers.udp_bus import CyclicUdpMulticastBus


def bus_medium(
    cfg: BusConfig, overrides: dict[str, Any] | None = None, index: int = 0
) -> tuple[str, str, dict[str, Any]]:
    """(interface, channel, python-can options) bus ``index`` of the config opens, after the
    ``overrides``: ``interface``, and ``channel`` (every bus on that one channel: their node
    ids must then differ) or ``channels`` (one per bus, by ``index``), and ``options``."""
    o = overrides or {}
    interface = o.get("interface") or cfg.interface
    channels = o.get("channels")
    channel = channels[index] if channels else (o.get("channel") or cfg.channel)
    kwargs: dict[str, Any] = dict(cfg.options)
    kwargs.update(o.get("options") or {})
    return interface, str(channel), kwargs


def media_of(
    buses: tuple[BusConfig, ...], overrides: dict[str, Any] | None = None
) -> list[int]:
    """The index of the first bus on each distinct medium: buses that an override puts on one
    channel share it, and a broadcast (SYNC, NMT, heartbeat) goes out once per medium — twice
    would be two SYNCs a cycle to every drive."""
    seen: dict[str, int] = {}
    for b, cfg in enumerate(buses):
        seen.setdefault(media_key(cfg, overrides, b), b)
    return sorted(seen.values())


def media_key(cfg: BusConfig, overrides: dict[str, Any] | None = None, index: int = 0) -> str:
    """What identifies the medium bus ``index`` opens: two buses with the same key share it."""
    interface, channel, kwargs = bus_medium(cfg, overrides, index)
    return repr((interface, channel, sorted(kwargs.items())))


def open_bus(cfg: BusConfig, overrides: dict[str, Any] | None = None, index: int = 0) -> can.BusABC:
    """A python-can bus for ``cfg`` (any interface: socketcan, virtual, udp_multicast, ...)
    on the medium ``bus_medium`` gives."""
    interface, channel, kwargs = bus_medium(cfg, overrides, index)
    if interface not in ("virtual", "udp_multicast", "inprocess", "socketpair"):
        kwargs.setdefault("bitrate", cfg.bitrate)
    try:
        if interface == "udp_multicast":  # python-can's, with a cyclic path (udp_bus.py)
            return CyclicUdpMulticastBus(channel, **kwargs)
        if interface == "socketpair":  # run --sim's simulated robot in its own process
            return PairBus(channel, **kwargs)
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except Exception as exc:  # python-can raises CanError, OSError, ImportError, ValueError...
        raise DriverInitializationError(
            f"cannot open CAN bus interface={interface!r} channel={channel!r}: "
            f"{type(exc).__name__}: {exc}{_hint(interface, exc)}"
        ) from exc


def _hint(interface: str, exc: Exception) -> str:
    """What to do about a bus that would not open, where the error alone does not say."""
    if interface == "socketcan" and getattr(exc, "errno", None) == errno.EAFNOSUPPORT:
        return ("; this kernel has no SocketCAN (modprobe can can_raw vcan; a container or a VM "
                "without it: docs/hil.md), or reach a simulated robot on udp_multicast "
                "(docs/drivers.md)")  # fmt: skip
    if interface == "socketcan" and getattr(exc, "errno", None) == errno.ENODEV:
        return "; no such interface: `ip link` lists them (bring it up: docs/drivers.md)"
    return ""


class TrafficLog:
    """Writes every frame sent and received to a python-can logger (``.log`` candump, ``.asc``,
    ``.blf``, ``.csv``, ...) from a background thread: the loop only enqueues."""

    def __init__(self, path: str):
        self._logger = can.Logger(path)
        self._q: queue.SimpleQueue[can.Message | None] = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name="can-log", daemon=True)
        self._thread.start()

    def __call__(self, msg: can.Message) -> None:
        self._q.put(msg)

    def _run(self) -> None:
        while True:
            msg = self._q.get()
            if msg is None:
                break
            self._logger.on_message_received(msg)

    def close(self) -> None:
        self._q.put(None)
        self._thread.join(timeout=2.0)
        self._logger.stop()
