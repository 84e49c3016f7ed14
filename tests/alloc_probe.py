"""Counting what the controller's cycle takes from the allocator, apart from the simulated
robot's (tests/control/cycle/test_allocations.py).

tracemalloc sees every block taken from Python's allocators and every numpy data buffer; the
free lists of floats and small tuples hand out no block and are not counted. A window around
``manager.step`` holds only the controller's side: the driver's buses are wrapped so that the
frames the simulated robot sent are taken off its bus before the window (and released after
it), and the frames the driver sends are handed to the bus after it — in the same order and
before the robot runs, as in lock-step they always were. Inside the window nothing allocated
elsewhere is freed, so any block taken there, even one freed again, raises the peak.
"""

from __future__ import annotations

import sys
import tracemalloc
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OURS = (str(ROOT / "cdprctl"), str(ROOT / "drivers"))
SLOTS = 512  # frames per bus and cycle, either way: far more than a cycle carries


class DeferredBus:
    """The driver's side of a bus: ``recv`` from frames taken off it before the window,
    ``send`` into a list handed to it after the window. Neither allocates."""

    def __init__(self, bus: Any):
        self.bus = bus
        self.inbox: list[Any] = [None] * SLOTS
        self.outbox: list[Any] = [None] * SLOTS
        self.n_in = self.taken = self.n_out = 0

    def before(self) -> None:
        n = 0
        while (msg := self.bus.recv(0)) is not None:
            self.inbox[n] = msg
            n += 1
        self.n_in, self.taken = n, 0

    def after(self) -> None:
        for i in range(self.n_out):
            self.bus.send(self.outbox[i], timeout=0)
            self.outbox[i] = None
        for i in range(self.n_in):
            self.inbox[i] = None
        self.n_out = self.n_in = self.taken = 0

    def recv(self, timeout: float | None = None) -> Any:
        if self.taken == self.n_in:
            return None
        msg = self.inbox[self.taken]
        self.taken += 1
        return msg

    def send(self, msg: Any, timeout: float | None = None) -> None:
        self.outbox[self.n_out] = msg
        self.n_out += 1

    def shutdown(self) -> None:
        """The driver's shut-down reaches the bus (left open, each was shut at the
        interpreter's exit: a traceback per bus in the suite's output)."""
        self.bus.shutdown()


def defer_buses(driver: Any) -> list[DeferredBus]:
    """Wrap each distinct bus of ``driver`` (buses on one medium share one)."""
    wrapped: dict[int, DeferredBus] = {}
    for b, bus in enumerate(driver.buses):
        driver.buses[b] = wrapped.setdefault(id(bus), DeferredBus(bus))
    return list(wrapped.values())


class Window:
    """``run(n)``: ``n`` lock-step cycles of ``cl`` (a ``ClosedLoop``), each controller step
    measured: ``net`` (bytes still held at its end) and ``peak`` (the most held within it),
    per cycle, against what was held at its start. tracemalloc must be tracing."""

    def __init__(self, cl: Any):
        self.cl = cl
        self.buses = defer_buses(cl.rig.driver)
        self.mark = np.zeros(1, dtype=np.int64)

    def run(self, n: int, each: Any = None) -> tuple[np.ndarray, np.ndarray]:
        cl, buses, mark = self.cl, self.buses, self.mark
        step, net, period = cl.manager.step, cl.net, cl.period
        grew, peaks = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        traced, reset = tracemalloc.get_traced_memory, tracemalloc.reset_peak
        for i in range(n):
            t = net.time
            for bus in buses:
                bus.before()
            mark[0] = traced()[0]  # the tuple is built after the figure is read, then freed
            reset()
            step(t)
            now, peak = traced()
            grew[i], peaks[i] = now - mark[0], peak - mark[0]
            for bus in buses:
                bus.after()
            if each is not None:
                each(cl)
            net.advance(period)
        return grew, peaks


def ours(filename: str) -> bool:
    return filename.startswith(OURS)


class LineProbe:
    """A line tracer over the controller's step: every line of cdprctl/ or drivers/ during
    which a block was taken (the peak rose), with the bytes, over the cycles run — the sites
    of temporaries, which no snapshot holds. Slow: a few cycles only. The frame object the
    tracing itself builds for each call (``FRAME`` bytes, measured) is not counted."""

    def __init__(self) -> None:
        self.sites: Counter[str] = Counter()
        self.where = ""
        self.mark = np.zeros(1, dtype=np.int64)
        self.local, self.glob = self._local, self._global  # bound once: no method per event
        self.frame_bytes = 0
        self.frame_bytes = self._measure_frame()

    def _measure_frame(self) -> int:
        def inner() -> None:
            pass

        def outer() -> None:
            inner()

        sites, self.sites = self.sites, Counter()
        self._restart("")
        sys.settrace(self.glob)
        try:
            outer()
        finally:
            sys.settrace(None)
        self.sites = sites
        return self.rose_at_call

    def _rose(self) -> int:
        return int(tracemalloc.get_traced_memory()[1] - self.mark[0])

    def _restart(self, where: str) -> None:
        self.where = where
        self.mark[0] = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()

    def _local(self, frame: Any, event: str, arg: Any) -> Any:
        if event in ("line", "return"):
            rose = self._rose()
            if rose > 0 and self.where:
                self.sites[self.where] += rose
            back = frame.f_back
            if event == "return" and back is not None and ours(back.f_code.co_filename):
                self._restart(f"{_short(back.f_code.co_filename)}:{back.f_lineno}")
            else:
                self._restart(f"{_short(frame.f_code.co_filename)}:{frame.f_lineno}")
        return self.local

    def _global(self, frame: Any, event: str, arg: Any) -> Any:
        self.rose_at_call = rose = self._rose() - self.frame_bytes
        if rose > 0 and self.where:  # the calling line's, before the call
            self.sites[self.where] += rose
        if not ours(frame.f_code.co_filename) and frame.f_code.co_filename != __file__:
            self._restart(self.where)  # Python code of a library: its blocks are the caller's
            return None
        self._restart(f"{_short(frame.f_code.co_filename)}:{frame.f_lineno}")
        return self.local

    def step(self, cl: Any, buses: list[DeferredBus]) -> None:
        """One lock-step cycle of ``cl``, its controller step traced."""
        t = cl.net.time
        for bus in buses:
            bus.before()
        self._restart("")
        sys.settrace(self.glob)
        try:
            cl.manager.step(t)
        finally:
            sys.settrace(None)
        for bus in buses:
            bus.after()
        cl.net.advance(cl.period)


def _short(filename: str) -> str:
    return str(Path(filename).relative_to(ROOT)) if filename.startswith(str(ROOT)) else filename


def peak_bytes(call: Any, calls: int = 1) -> int:
    """Bytes taken from the allocator at the peak of ``calls`` (1-3) calls of ``call``, after one
    call outside the window (compiled, or loaded from numba's cache) and the float free list
    primed as the loop primes it; the window itself builds no object."""
    call()
    floats = [i * 0.5 for i in range(100)]  # given back to their free list, as in the loop
    del floats
    mark = np.zeros(1, dtype=np.int64)
    tracemalloc.start()
    try:
        mark[0] = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        call()  # unrolled: a loop's iterator would be a block in the window
        if calls > 1:
            call()
        if calls > 2:
            call()
        return int(tracemalloc.get_traced_memory()[1] - mark[0])
    finally:
        tracemalloc.stop()
