"""Timing helpers for the benchmarks: medians and p99 of many single calls.

The machines are shared and noisy: each measurement runs in several rounds; we report the
median and p99 over all calls, and the lowest round median (the quiet-machine figure).
"""

from __future__ import annotations

import gc
import os
import socket
import time
from collections.abc import Callable

import numpy as np


def time_calls(
    fn: Callable[[], object], n: int = 20000, warmup: int = 500, rounds: int = 5
) -> list[np.ndarray]:
    """Per-call wall times (µs) of ``fn``: ``rounds`` arrays of ``n // rounds`` calls each,
    garbage collection off during the runs."""
    for _ in range(warmup):
        fn()
    out = []
    per = max(1, n // rounds)
    clock = time.perf_counter_ns
    for _ in range(rounds):
        samples = np.empty(per)
        gc.collect()
        gc.disable()
        try:
            for i in range(per):
                t0 = clock()
                fn()
                samples[i] = clock() - t0
        finally:
            gc.enable()
        out.append(samples / 1000.0)
    return out


def stats(rounds: list[np.ndarray]) -> tuple[float, float, float]:
    """(median, p99, best round median) in µs."""
    allv = np.concatenate(rounds)
    return (
        float(np.median(allv)),
        float(np.percentile(allv, 99)),
        float(min(np.median(r) for r in rounds)),
    )


def row(name: str, rounds: list[np.ndarray], goal: float | None = None) -> str:
    med, p99, best = stats(rounds)
    goal_s = "" if goal is None else f"  goal <= {goal:g}: {'OK' if med <= goal else 'MISSED'}"
    return f"{name:<40} median {med:8.2f} µs  p99 {p99:8.2f} µs  best round {best:8.2f}{goal_s}"


def ufunc_overhead() -> float:
    """Median µs of one tiny numpy ufunc call (np.add on 8×3, out=): the per-call overhead that
    dominates 8-cable maths. It swings 2-4x on these shared VMs; quote it with every figure."""
    a, b, o = np.zeros((8, 3)), np.ones((8, 3)), np.zeros((8, 3))
    rounds = time_calls(lambda: np.add(a, b, out=o), n=20000, rounds=5)
    return float(np.median(np.concatenate(rounds)))


def machine_line() -> str:
    import platform

    load = os.getloadavg()
    return (
        f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}, "
        f"{os.cpu_count()} cores, load average {load[0]:.2f}; numpy ufunc call "
        f"{ufunc_overhead():.2f} µs (0.6-0.7 µs when the VM is quiet)"
    )


def free_port() -> int:
    """A TCP port free on 127.0.0.1 now, for a daemon the benchmark starts."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])
