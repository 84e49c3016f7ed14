"""Benchmark: the machine's floor for compute jitter — what a fixed piece of C work costs at
its median and p99 when run once a period at the loop's priority and CPU, as cyclictest is the
floor for wake-ups.

A cycle's compute p99 is judged against its median on this shared VM: a p99/p50 of ~2 for the
controller could be the interpreter, or the host. Here the same work every period (a fixed
chain of floating-point multiply-adds sized to ``--work`` µs on a quiet start, nothing
allocated, no system call inside the timed part), at ``SCHED_FIFO`` ``--priority`` on the
loop's CPU, ``--hog N`` busy processes beside it: its p50, p99 and max, and p99/p50. The
controller's ratio above this one is the controller's own; at or below it, the machine's.

Run: ``.venv/bin/python benchmarks/bench_compute_floor.py [--seconds 15] [--rate 1000]
[--work 200] [--hog 0]``. Needs a C compiler (cc); SCHED_FIFO needs root.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import bench_parser, busy_processes, loop_options, machine_line
from bench_floor import PRIORITY

SOURCE = r"""
#define _GNU_SOURCE
#include <sched.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_ns(void) {
    struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec * 1e9 + t.tv_nsec;
}
static volatile double sink;
static double work(long n) {  /* a dependent chain: no vectorising it away */
    double x = 1.0;
    for (long i = 0; i < n; i++) x = x * 1.0000001 + 1e-9;
    return x;
}
int main(int argc, char **argv) {
    long period_ns = atol(argv[1]), cycles = atol(argv[2]), n = atol(argv[3]);
    struct timespec next; clock_gettime(CLOCK_MONOTONIC, &next);
    for (long c = 0; c < cycles; c++) {
        next.tv_nsec += period_ns;
        while (next.tv_nsec >= 1000000000L) { next.tv_nsec -= 1000000000L; next.tv_sec++; }
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
        double t0 = now_ns();
        sink = work(n);
        printf("%.0f\n", now_ns() - t0);
    }
    return 0;
}
"""


def build(tmp: Path) -> str:
    src, exe = tmp / "floor.c", tmp / "floor"
    src.write_text(SOURCE)
    subprocess.run(["cc", "-O2", "-o", str(exe), str(src)], check=True)
    return str(exe)


def run(exe: str, period_ns: int, cycles: int, n: int, cpu: int, priority: int) -> np.ndarray:
    """Per-cycle work durations (µs) at ``SCHED_FIFO`` ``priority`` on ``cpu``."""

    def setup() -> None:
        os.sched_setaffinity(0, {cpu})
        with contextlib.suppress(PermissionError):  # then the normal scheduler
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))

    out = subprocess.run([exe, str(period_ns), str(cycles), str(n)], capture_output=True,
                         text=True, preexec_fn=setup, check=True).stdout  # fmt: skip
    return np.array([float(x) for x in out.split()]) / 1e3


def main() -> None:
    ap = bench_parser(__doc__)
    loop_options(ap, seconds=15.0, rate=1000.0)
    ap.add_argument("--work", type=float, default=200.0, help="µs of work a cycle (calibrated)")
    ap.add_argument("--hog", type=int, default=0, help="busy processes beside it")
    ap.add_argument("--priority", type=int, default=PRIORITY)
    args = ap.parse_args()
    print(machine_line())
    cpu = max(os.sched_getaffinity(0))
    period_ns = int(1e9 / args.rate)
    with tempfile.TemporaryDirectory() as tmp:
        exe = build(Path(tmp))
        probe = run(exe, period_ns, 200, 100_000, cpu, args.priority)
        n = int(100_000 * args.work / float(np.median(probe[50:])))
        with busy_processes(args.hog):
            d = run(exe, period_ns, int(args.seconds * args.rate), n, cpu, args.priority)
    p50, p99 = float(np.median(d)), float(np.percentile(d, 99))
    print(f"CPU {cpu}, SCHED_FIFO {args.priority}, {args.rate:g} Hz, {args.hog} hogs, "
          f"{len(d)} cycles of fixed C work: p50 {p50:.0f} us, p99 {p99:.0f} us, max "
          f"{d.max():.0f} us; p99/p50 {p99 / p50:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
