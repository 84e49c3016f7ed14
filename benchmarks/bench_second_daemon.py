"""A second daemon's first start beside a running one, on the same CPU (``cpu = -1``: the last).

Daemon A (its kernels cached) runs the simulated robot, real-time, without a demo; daemon B
starts with an empty numba cache (a machine's first run: about a minute of compiles), runs a
few seconds and stops. The figure: A's missed periods while B starts, runs and stops, and
whether A faulted. With the start-up at SCHED_FIFO, B's compiles held A's CPU for seconds (a
lost heartbeat, a fault); the start-up and shut-down now run at the normal scheduler.

    .venv/bin/python benchmarks/bench_second_daemon.py [--tree DIR_FOR_B] [--seconds 5]

``--tree``: a checkout to run B from (another commit, to compare); A runs from this one.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUN = ["-m", "cdprctl.cli", "run", "--config", "config/rowc.toml", "--sim", "--rate", "250",
       "--no-demo"]  # fmt: skip


def missed(lines: list[str]) -> int:
    got = [int(m.group(1)) for x in lines if (m := re.search(r"missed (\d+)$", x.strip()))]
    return got[-1] if got else -1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tree", default=str(ROOT), help="the checkout B runs from")
    ap.add_argument("--seconds", type=float, default=5.0, help="B's run after its start-up")
    a = ap.parse_args()
    with tempfile.TemporaryFile("w+") as a_out, tempfile.TemporaryDirectory() as cache:
        first = subprocess.Popen([sys.executable, *RUN, "--status", "1"], cwd=ROOT,
                                 stdout=a_out, stderr=subprocess.STDOUT, text=True)  # fmt: skip
        try:
            time.sleep(8.0)  # A's start-up (cached kernels) and a few seconds of its loop
            a_out.seek(0)
            before = missed(a_out.read().splitlines())
            t0 = time.monotonic()
            second = subprocess.run(
                [sys.executable, *RUN, "--duration", str(a.seconds)], cwd=a.tree,
                env={**os.environ, "NUMBA_CACHE_DIR": cache}, capture_output=True, text=True,
                timeout=600,
            )  # fmt: skip
            b_took = time.monotonic() - t0
            time.sleep(2.0)
        finally:
            first.send_signal(signal.SIGTERM)
            first.wait(timeout=30)
        a_out.seek(0)
        lines = a_out.read().splitlines()
    fault = next((x for x in lines if "FAULT" in x), "")
    b_summary = next((x.strip() for x in second.stdout.splitlines() if "cycles" in x), "?")
    print(f"B ({a.tree}): exit {second.returncode} after {b_took:.0f} s; {b_summary}")
    print(f"A: missed periods {before} before B, {missed(lines)} at the end"
          f"{'; ' + fault.strip() if fault else '; no fault'}")
    print(f"machine: load {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs")
    return 0


if __name__ == "__main__":
    sys.exit(main())
