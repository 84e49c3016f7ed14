"""Benchmark: what the Zenoh gateway costs the loop. The daemon on the simulated robot
(in-process, 500 Hz or --rate, the 20 s demo motion) without the gateway, then with it publishing
`state` at 100 Hz while this process floods it with 1000 commands/s (mostly rejected by the
gateway — malformed JSON, targets outside the workspace — and 10/s valid `set_tda` that reach
the loop); runs alternate A, B, A, B so the VM's drift hits both. Reports wake lateness
p50/p99/max, compute p50 and missed periods per run, and the ratio of the p99s (goal: B no
more than 10 % worse than A).

Run: ``.venv/bin/python benchmarks/bench_telemetry.py [--rounds 2] [--seconds 20]``.
"""

from __future__ import annotations

import argparse
import json
import re
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _timing import machine_line

ROOT = Path(__file__).resolve().parents[1]
SUMMARY = re.compile(
    r"wake lateness p50 ([\d.]+) us, p99 ([\d.]+) us, max ([\d.]+) us; compute p50 ([\d.]+) us"
    r".*missed periods (\d+) \(([\d.]+) %\)"
)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def flood(endpoint: str, stop: threading.Event, counter: dict[str, int]) -> None:
    sys.path.insert(0, str(ROOT))
    import os

    from cdprctl.telemetry.session import open_session

    # this thread (and the Zenoh threads its session starts) off the loop's CPU (the last):
    # the flood stands for operators on other machines, not for load on the robot PC
    cpus = sorted(os.sched_getaffinity(0))
    if len(cpus) > 1:
        os.sched_setaffinity(0, set(cpus[:-1]))
    session = open_session(connect=[endpoint], multicast_scouting=False)
    bad = [b"{nonsense", json.dumps({"position": [9.0, 0.35, 0.5]}).encode()]
    good = json.dumps({"method": "barycenter"}).encode()
    period = 0.001
    next_t = time.monotonic()
    i = 0
    try:
        while not stop.is_set():
            if i % 100 == 0:
                session.put("cdpr/rowc/cmd/set_tda", good)
            else:
                session.put("cdpr/rowc/cmd/move", bad[i % 2])
            i += 1
            next_t += period
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    finally:
        counter["sent"] = i
        session.close()


def run_once(seconds: float, gateway: bool, rate: float) -> dict[str, float]:
    cmd = [sys.executable, "-m", "cdprctl.cli", "run", "--config", str(ROOT / "config/rowc.toml")]
    cmd += ["--sim", "--status", "0", "--duration", str(seconds), "--rate", str(rate)]
    endpoint = ""
    if gateway:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        cmd += ["--zenoh", "--accept-commands", "--zenoh-listen", endpoint]
        cmd += ["--no-multicast-scouting"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    stop = threading.Event()
    counter: dict[str, int] = {}
    flooder = None
    lines = []
    assert proc.stdout is not None
    for line in proc.stdout:
        lines.append(line)
        if line.startswith("ready:") and gateway:
            flooder = threading.Thread(target=flood, args=(endpoint, stop, counter))
            flooder.start()
        if line.startswith("summary:"):
            break
    lines += proc.stdout.readlines()
    stop.set()
    if flooder is not None:
        flooder.join()
    proc.wait()
    text = "".join(lines)
    m = SUMMARY.search(text)
    if not m:
        raise RuntimeError("no summary:\n" + text[-2000:])
    p50, p99, mx, comp, missed, pct = m.groups()
    return {
        "p50": float(p50),
        "p99": float(p99),
        "max": float(mx),
        "compute": float(comp),
        "missed": float(missed),
        "pct": float(pct),
        "sent": float(counter.get("sent", 0)),
        "rejects": float(text.count("rejected")),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--rate", type=float, default=500.0, help="loop rate, Hz")
    args = ap.parse_args()
    print(machine_line())
    results: dict[bool, list[dict[str, float]]] = {False: [], True: []}
    for r in range(args.rounds):
        for gateway in (False, True):
            res = run_once(args.seconds, gateway, args.rate)
            results[gateway].append(res)
            label = "gateway + flood" if gateway else "no gateway     "
            extra = f", {res['sent']:.0f} commands sent" if gateway else ""
            print(
                f"round {r + 1} {label}: lateness p50 {res['p50']:.1f} p99 {res['p99']:.1f} "
                f"max {res['max']:.0f} us, compute p50 {res['compute']:.0f} us, missed "
                f"{res['missed']:.0f} ({res['pct']:.3f} %){extra}",
                flush=True,
            )
    import statistics

    for key, what in (
        ("p99", "p99 lateness us"),
        ("compute", "compute p50 us"),
        ("pct", "missed %"),
    ):
        a = statistics.median(x[key] for x in results[False])
        b = statistics.median(x[key] for x in results[True])
        ratio = f": ratio {b / a:.2f}" if a > 0 else ""
        print(f"median over rounds, {what}: {a:.3f} without, {b:.3f} with{ratio}")


if __name__ == "__main__":
    main()
