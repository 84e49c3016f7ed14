"""Benchmark: what the ROS 2 link (`cdprctl run --ros2`, docs/ros2.md) costs the loop.

Each round: C's ``cyclictest`` at the loop's period, priority and CPU (the machine's floor,
``bench_floor.floor``), then the daemon on the simulated robot (rowc, the demo motion, 500 Hz or
--rate) without the link (A) and with it (B), in alternating order from round to round, B on
DDS domain 37 with an independent subscriber (``tests/ros2_subscriber.py``: its own types, its
own participant, another process) taking every topic for the whole run — in A too, where it
takes nothing: both runs carry the same subscriber, the difference is the link. Each run saves its
per-cycle timing (``--timing-file``). Reports per run and pooled: wake lateness p50/p99/max,
compute p50/p99, missed periods, the messages the subscriber received, the B/A ratios and the
daemon's lateness p99 over the floor's.

Run: ``.venv/bin/python benchmarks/bench_ros2.py [--rounds 3] [--seconds 20] [--rate 500]
[--domain 37]`` (the DDS domain of B's link and of the subscriber).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import (
    ab_arguments,
    loop_stats,
    machine_line,
    pooled_loop_stats,
    timed_daemon_run,
)
from bench_floor import PRIORITY, ensure_cyclictest, floor

ROOT = Path(__file__).resolve().parents[1]
DOMAIN = 37


def run_once(seconds: float, ros2: bool, rate: float, timing: Path,
             domain: int = DOMAIN) -> tuple[dict, dict]:  # fmt: skip
    """One daemon run and what the subscriber got (``tests/ros2_subscriber.py``'s line)."""
    got: dict = {}

    def subscribe() -> None:  # until the run's end, less its start-up
        out = subprocess.run([sys.executable, str(ROOT / "tests" / "ros2_subscriber.py"),
                              str(domain), "cdpr/rowc", str(max(1.0, seconds - 2.0))],
                             capture_output=True, text=True, timeout=seconds + 60)  # fmt: skip
        lines = out.stdout.strip().splitlines()
        got.update(json.loads(lines[-1]) if lines else {"error": out.stderr[-500:]})

    def start() -> threading.Thread:  # in A too: the same load, with nothing to take
        th = threading.Thread(target=subscribe)
        th.start()
        return th

    args = ["--duration", str(seconds), "--rate", str(rate)] + (["--ros2"] if ros2 else [])
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    return timed_daemon_run(args, timing, start, env), got


def main() -> None:
    args = ab_arguments(domain=(int, DOMAIN))
    exe = ensure_cyclictest()
    print(machine_line())
    pooled: dict[bool, list[dict]] = {False: [], True: []}
    floors = []
    with tempfile.TemporaryDirectory() as d:
        for r in range(args.rounds):
            fl = floor(exe, 1.0 / args.rate, min(10.0, args.seconds), cpu=1, priority=PRIORITY)
            floors.append(fl)
            print(f"round {r + 1} floor   : cyclictest p99 {fl['p99_us']:.0f} max "
                  f"{fl['max_us']:.0f} µs", flush=True)  # fmt: skip
            for ros2 in ((False, True) if r % 2 == 0 else (True, False)):
                data, got = run_once(args.seconds, ros2, args.rate, Path(d) / f"{r}{ros2}.npz",
                                     args.domain)  # fmt: skip
                s = loop_stats(data)
                pooled[ros2].append(data)
                counts = got.get("counts", {})
                heard = (f"; subscriber: joint_states {counts.get('joint_states', 0)}, tf "
                         f"{counts.get('tf', 0)}, pose {counts.get('pose', 0)} in "
                         f"{max(1.0, args.seconds - 2.0):g} s"
                         + (f" ({got['error']})" if "error" in got else ""))
                print(f"round {r + 1} {'B ros2 ' if ros2 else 'A none '}: lateness p50 "
                      f"{s['late_p50']:.1f} p99 {s['late_p99']:.1f} max {s['late_max']:.0f} µs;"
                      f" compute p50 {s['compute_p50']:.0f} p99 {s['compute_p99']:.0f} µs; "
                      f"missed {s['missed']:.0f} of {s['cycles']:.0f}{heard}",
                      flush=True)  # fmt: skip
    a, b = pooled_loop_stats(pooled[False]), pooled_loop_stats(pooled[True])
    fl99 = float(np.median([f["p99_us"] for f in floors]))
    print(f"pooled: lateness p99 A {a['late_p99']:.1f} µs, B {b['late_p99']:.1f} µs, the "
          f"floor's (median of the rounds' cyclictest p99) {fl99:.0f} µs: A/floor "
          f"{a['late_p99'] / fl99:.2f}, B/floor {b['late_p99'] / fl99:.2f}; max A "
          f"{a['late_max']:.0f}, B {b['late_max']:.0f} µs; compute p99 A "
          f"{a['compute_p99']:.0f}, B {b['compute_p99']:.0f} µs "
          f"(B/A {b['compute_p99'] / a['compute_p99']:.2f}); missed A {a['missed']:.0f} of "
          f"{a['cycles']:.0f}, B {b['missed']:.0f} of {b['cycles']:.0f}")  # fmt: skip


if __name__ == "__main__":
    main()
