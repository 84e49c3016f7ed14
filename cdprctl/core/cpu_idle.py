"""The machine's CPUs kept awake while a real-time loop runs: the kernel's PM QoS request
(``/dev/cpu_dma_latency``), held open with the longest wake-up latency allowed, as
``cyclictest`` holds it for the whole of its run (rt-tests: 0 unless ``--laptop``).

Why the loop needs it: an idle CPU halts, and waking it is slow — a virtual CPU's halt is a
trip to the host. A frame the loop sends to a peer waiting on the other CPU (the simulated
robot's process, ``cdprctl sim``, a candump) wakes that CPU inside the loop's ``send``:
21 µs a send on this VM (p50; 7 µs with the CPUs kept out of the halt), and every phase of a
cycle ran slower after the loop's own CPU had halted. rowc at 1 kHz in ``run --sim``, quiet,
20 s each, alternating: compute p50/p99 191/434 and 196/396 µs without, 164/257 and 166/250
µs with (2026-12-07). The cost: idle CPUs poll instead of halting (power, and a host's
CPU time under a VM) while the loop runs; ``[control.realtime] cpu_wakeup_latency = -1``
leaves the machine's idle states alone.
"""

from __future__ import annotations

import contextlib
import os
import struct

#: the kernel's PM QoS device for the CPUs' wake-up latency (µs, a native 32-bit integer)
PM_QOS_DEVICE = "/dev/cpu_dma_latency"


class CpuWakeupLatency:
    """One PM QoS request, held from ``hold`` to ``release`` (or the process's end: the kernel
    drops a request when its file is closed)."""

    def __init__(self, device: str | None = None):
        """``device``: the PM QoS file (default ``PM_QOS_DEVICE``, read at the call)."""
        self.device = device or PM_QOS_DEVICE
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def hold(self, latency: float) -> list[str]:
        """Keep every CPU out of idle states slower to wake than ``latency`` s (negative:
        nothing asked). Returns a warning where the request could not be made."""
        if latency < 0 or self._fd is not None:
            return []
        micros = round(latency * 1e6)
        try:
            fd = os.open(self.device, os.O_WRONLY | os.O_CLOEXEC)
        except OSError as exc:
            return [self._refused(micros, exc)]
        try:
            os.write(fd, struct.pack("=i", micros))
        except OSError as exc:
            os.close(fd)
            return [self._refused(micros, exc)]
        self._fd = fd
        return []

    def release(self) -> None:
        """The request withdrawn (idempotent)."""
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._fd)
            self._fd = None

    def _refused(self, micros: int, exc: OSError) -> str:
        return (
            f"CPU wake-up latency of {micros} µs not held ({self.device}: {exc.strerror}): idle "
            "CPUs halt and a frame to a peer waiting on one wakes it inside the loop's send; "
            f"give the service write access to {self.device} (systemd/99-cdprctl.rules) or set "
            "[control.realtime] cpu_wakeup_latency = -1"
        )
