"""Timing helpers for the benchmarks: medians and p99 of many single calls.

The machines are shared and noisy: each measurement runs in several rounds; we report the
median and p99 over all calls, and the lowest round median (the quiet-machine figure).
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

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


def loop_stats(data: dict, settle: float = 1.0) -> dict[str, float]:
    """A daemon run's per-cycle timing (``--timing-file``), its first ``settle`` s left out
    (the start): wake lateness and compute p50/p99 (µs), missed periods, cycles."""
    t = data["deadline"]
    keep = t >= t[0] + settle
    late = data["lateness"][keep] * 1e6
    comp = data["compute"][keep] * 1e6
    gaps = np.round(np.diff(t) / float(data["period"])) - 1.0
    return {"late_p50": float(np.median(late)), "late_p99": float(np.percentile(late, 99)),
            "late_max": float(late.max()), "compute_p50": float(np.median(comp)),
            "compute_p99": float(np.percentile(comp, 99)), "missed": float(gaps[gaps > 0].sum()),
            "cycles": float(keep.sum())}  # fmt: skip


def pooled_loop_stats(runs: list[dict]) -> dict[str, float]:
    """``loop_stats`` of several runs' cycles pooled (each after its first second); missed
    periods summed run by run (the gaps between runs are none)."""
    trimmed = []
    for x in runs:
        k = x["deadline"] >= x["deadline"][0] + 1.0
        trimmed.append({f: x[f][k] for f in ("deadline", "lateness", "compute")})
    merged = {"deadline": np.concatenate([x["deadline"] - x["deadline"][0] + 1e4 * i
                                          for i, x in enumerate(trimmed)]),
              "lateness": np.concatenate([x["lateness"] for x in trimmed]),
              "compute": np.concatenate([x["compute"] for x in trimmed]),
              "period": runs[0]["period"]}  # fmt: skip
    out = loop_stats(merged, settle=0.0)
    out["missed"] = sum(loop_stats(x)["missed"] for x in runs)
    return out


def timed_daemon_run(args: list[str], timing: Path, on_ready: Callable[[], object] | None = None,
                     env: dict[str, str] | None = None) -> dict:  # fmt: skip
    """``cdprctl run --sim`` on rowc with ``args``, its per-cycle timing saved to ``timing``
    and returned (``--timing-file``); ``on_ready()`` called when it prints ``ready:`` (a
    client started then), its result's ``join()``, if it has one, after the run."""
    root = Path(__file__).resolve().parents[1]
    cmd = [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(root / "config/rowc.toml"),
           "--sim", "--status", "0", "--timing-file", str(timing), *args]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env)  # fmt: skip
    lines, started = [], None
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("ready:") and on_ready is not None:
            started = on_ready()
        if line.startswith("summary:"):
            break
    lines += proc.stdout.readlines()
    proc.wait()
    join = getattr(started, "join", None)
    if join is not None:
        join()
    if proc.returncode != 0 or not timing.exists():
        raise RuntimeError("the daemon failed:\n" + "".join(lines)[-2000:])
    with np.load(timing) as z:
        return {k: z[k] for k in z.files}


def bench_parser(doc: str | None) -> argparse.ArgumentParser:
    """A benchmark's options, described by the first paragraph of its docstring ``doc``."""
    return argparse.ArgumentParser(description=None if doc is None else doc.split("\n\n")[0])


def loop_options(ap: argparse.ArgumentParser, seconds: float, rate: float) -> None:
    """The options of a benchmark that runs a loop: ``--seconds`` of each run (default
    ``seconds``), ``--rate`` the loop's rate in Hz (default ``rate``)."""
    ap.add_argument("--seconds", type=float, default=seconds, help="s of each run")
    ap.add_argument("--rate", type=float, default=rate, help="the loop's rate, Hz")


def ab_arguments(**more: tuple[type, object]) -> argparse.Namespace:
    """The A/B loop benchmarks' options: rounds, seconds a run, the loop's rate (Hz), and
    ``more`` (name → (type, default))."""
    ap = bench_parser(None)
    ap.add_argument("--rounds", type=int, default=3)
    loop_options(ap, seconds=20.0, rate=500.0)
    for name, (kind, default) in more.items():
        ap.add_argument(f"--{name}", type=kind, default=default)
    return ap.parse_args()


@contextlib.contextmanager
def busy_processes(n: int) -> Iterator[None]:
    """``n`` busy Python processes at normal priority for the duration (the machine's other
    work: a camera node, a build), killed at the end — a SIGTERM to the benchmark too (it
    left them running, and every later measurement beside them)."""

    def terminated(*_: object) -> None:
        raise SystemExit(143)

    old = signal.signal(signal.SIGTERM, terminated)
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for h in hogs:
            h.kill()
            h.wait()
        signal.signal(signal.SIGTERM, old)
